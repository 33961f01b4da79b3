"""`r2s VERB --help`: defaults, an example that runs on the shipped data, the exit codes; config presets by name."""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys

import pytest

from pipeline.cli import EXAMPLES, VERBS, build_parser
from tests.support import ROOT, assert_one_line_error, run_r2s


def _options(parser: argparse.ArgumentParser):
    return [a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]


@pytest.mark.parametrize("verb", VERBS)
def test_help_shows_defaults_an_example_and_the_exit_codes(verb):
    parser = build_parser(verb)
    text = parser.format_help()
    assert "example (from the repository's root):" in text and "exit codes: 0 done; 2 bad input" in text
    assert all(f"  {line}" in text for line in EXAMPLES[verb])
    for action in _options(parser):
        if action.default is not None and action.default is not False:
            assert "default" in parser._get_formatter()._get_help_string(action), (verb, action.option_strings)
    assert ("3 the program does not contain the scene" in text) == (verb == "check")
    assert ("4 " in text.split("exit codes:")[1]) == (verb in ("sample", "render", "simulate"))


def test_the_sampling_exit_code_is_the_one_sampling_raises():
    from pipeline.cli import MORE_EXIT_CODES
    from pipeline.simulation import NoVariantWritten
    from pipeline.variants.sample import SamplingFailed
    from synth.errors import ExitCode

    assert SamplingFailed.exit_code == NoVariantWritten.exit_code == ExitCode.SAMPLING_FAILED
    assert all(MORE_EXIT_CODES[v].startswith(f"{ExitCode.SAMPLING_FAILED} ") for v in ("sample", "render", "simulate"))


def test_top_level_help_lists_the_exit_codes():
    proc = run_r2s("--help")
    assert proc.returncode == 0 and "exit codes: 0 done" in proc.stdout and "docs/spec.md" in proc.stdout


def test_every_verb_has_an_example_that_uses_the_verb():
    assert set(EXAMPLES) == set(VERBS)
    for verb, lines in EXAMPLES.items():
        assert lines[-1].startswith(f"r2s {verb} "), verb


def test_every_help_example_runs(tmp_path):
    """Each example line, as written, from a directory that has the shipped data where the repository's root has
    it; a line several examples share (the one making scene.json) runs once, before the first example needing it."""
    (tmp_path / "data").symlink_to(ROOT / "data")
    done: set[str] = set()
    for verb, lines in EXAMPLES.items():
        for line in lines:
            if line in done:
                continue
            done.add(line)
            args = shlex.split(line)
            assert args[0] == "r2s"
            proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *args[1:]], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=300)
            assert proc.returncode == 0, f"r2s {verb} --help example: {line}\n{proc.stderr[-2000:]}"
    # What the examples say they make is there.
    for made in ("scene.json", "result.json", "scene.dsl", "frames", "programs", "matches.parquet",
                 "report/report.html", "scene.png", "variants/sample_004.json", "eval/metrics.json",
                 "simulated/summary.json", "simulated-clips/_simulations"):
        assert (tmp_path / made).exists(), made
    assert json.loads((tmp_path / "result.json").read_text())["status"] == "optimal"


# ------------------------------------------------------------------------------------------------ config presets

def test_presets_are_the_shipped_files_and_resolve_by_name(tmp_path):
    from pipeline.cli.inputs import load_config, preset_names

    assert preset_names() == sorted(p.stem for p in (ROOT / "configs").glob("*.toml")) == ["default", "paper"]
    assert load_config("paper") == load_config(str(ROOT / "configs" / "paper.toml"))
    assert load_config("default") == load_config(None)
    paper = load_config("paper")
    assert (paper.strategy, paper.oracle) == ("bfs-cpa", "smt")
    # A file of a preset's name wins (a path always works).
    (tmp_path / "paper").write_text("[synth]\ndelta1 = 7\n")
    proc = subprocess.run([sys.executable, "-c", "from pipeline.cli.inputs import load_config; "
                           "print(load_config('paper').delta1)"], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0 and float(proc.stdout) == 7.0, proc.stderr


def test_presets_are_package_data():
    """Found through the installed package, not the working directory."""
    proc = subprocess.run([sys.executable, "-c", "from importlib.resources import files; "
                           "print(files('configs').joinpath('paper.toml').read_text())"],
                          cwd="/", capture_output=True, text=True)
    assert proc.returncode == 0 and 'strategy = "bfs-cpa"' in proc.stdout, proc.stderr


def test_an_unknown_preset_names_the_closest(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps({"entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}]}))
    assert_one_line_error(run_r2s("synth", str(scene), "--config", "papr"), 2, "did you mean 'paper'")
    proc = run_r2s("synth", str(scene), "--config", "paper", "--format", "json")
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("verb", ["extract", "scene", "synth", "check"])
def test_help_does_not_load_pandas(verb):
    # `r2s VERB --help` builds the verb's parser only; pandas (~0.2 s of CPU) loads where rows are read.
    code = (f"import sys\nfrom pipeline.cli import build_parser\nbuild_parser({verb!r}).format_help()\n"
            "print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "False", verb


# ------------------------------------------------------------------------------------ a failing background thread

_THREAD = """
import sys, threading
from pipeline.cli import thread_failed_hook
threading.excepthook = thread_failed_hook("run")
t = threading.Thread(target=lambda: {}["work item 7"], name="ExecutorManagerThread")
t.start(); t.join()
print("main went on")
"""


@pytest.mark.parametrize("debug", [False, True])
def test_a_failing_background_thread_is_one_line_not_a_traceback(debug):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("R2S_DEBUG", None)
    if debug:
        env["R2S_DEBUG"] = "1"
    proc = subprocess.run([sys.executable, "-c", _THREAD], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=60)
    assert proc.returncode == 0 and proc.stdout == "main went on\n"
    if debug:
        assert "Traceback" in proc.stderr and "KeyError" in proc.stderr
    else:
        assert proc.stderr == ("r2s run: internal error in background thread ExecutorManagerThread: KeyError: "
                               "'work item 7' (R2S_DEBUG=1 shows the traceback)\n")
