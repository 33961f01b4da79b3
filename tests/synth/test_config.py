"""Configuration files and their defaults."""

from __future__ import annotations

import tomllib

import pytest

from synth.config import ConfigError, SynthConfig, config_from_mapping
from tests.support import ROOT


def test_default_toml_is_exactly_the_built_in_defaults():
    raw = tomllib.loads((ROOT / "configs" / "default.toml").read_text())
    assert config_from_mapping(raw) == SynthConfig()


def test_paper_toml_is_the_papers_setup():
    cfg = config_from_mapping(tomllib.loads((ROOT / "configs" / "paper.toml").read_text()))
    assert (cfg.delta1, cfg.delta2, cfg.c_dist, cfg.c_head) == (10.0, 5.0, 5.0, 5.0)
    assert (cfg.strategy, cfg.oracle) == ("bfs-cpa", "smt")


@pytest.mark.parametrize("bad", [{"delta1": 0}, {"delta2": 60}, {"c_dist": 0.001}, {"strategy": "magic"},
                                 {"oracle": "psychic"}, {"time_limit": -1}, {"delta1": float("nan")}])
def test_out_of_range_values_are_refused(bad):
    with pytest.raises(ConfigError):
        config_from_mapping(bad)


def test_semantic_hash_changes_with_what_decides_the_program():
    a = SynthConfig()
    assert a.semantic_hash() == SynthConfig().semantic_hash()
    assert a.semantic_hash() != a.with_(delta1=8.0).semantic_hash()
    assert a.semantic_hash() != a.with_(strategy="bfs-cpa").semantic_hash()


def test_an_int_and_the_same_float_are_one_setting():
    from synth.config import SynthConfig

    assert SynthConfig(time_limit=10, pos_uncertainty=1).semantic_hash() == \
        SynthConfig(time_limit=10.0, pos_uncertainty=1.0).semantic_hash()
    assert SynthConfig(time_limit=10).semantic_hash() != SynthConfig(time_limit=11).semantic_hash()


def test_monolithic_is_refused_with_dreal_instead_of_running_z3_under_its_name():
    SynthConfig(strategy="monolithic", solver="z3")  # the paper's Pure-SMT baseline
    with pytest.raises(ConfigError, match="monolithic .* --solver z3"):
        SynthConfig(strategy="monolithic", solver="dreal")
