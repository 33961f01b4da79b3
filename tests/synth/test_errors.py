"""One error root: every exception class of the project descends from R2sError through one kind, the kind decides
the exit code, the CLI maps it in one place, and docs/cli.md's table lists exactly the codes of synth.errors."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import subprocess
import sys

import pytest

import extractors
import frames
import pipeline
import synth
from synth.errors import KINDS, CheckFailed, ExitCode, InputError, InternalError, R2sError, SamplingError
from tests.support import ROOT


def _project_exception_classes() -> list[type[BaseException]]:
    found = []
    for package in (synth, frames, extractors, pipeline):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.endswith(".__main__"):  # runs the command when imported
                continue
            module = importlib.import_module(info.name)
            found += [obj for obj in vars(module).values()
                      if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == info.name]
    return found


def test_every_exception_class_has_the_root_and_one_kind_whose_exit_code_it_keeps():
    classes = _project_exception_classes()
    names = {c.__name__ for c in classes}
    # the classes the issue names (a walk that found none of them would prove nothing)
    assert {"SceneError", "DslError", "ConfigError", "SolverUnavailable", "FramesError", "ExtractError",
            "ProgramsError", "SamplingFailed", "ScenicProgramError", "SpeedMissing", "CertificationError",
            "NotGenerated", "NoVariant", "RefusedGlobal", "UserError"} <= names
    for cls in classes:
        if cls is R2sError or cls in KINDS:
            continue
        assert issubclass(cls, R2sError), cls
        kinds = [k for k in KINDS if issubclass(cls, k)]
        assert len(kinds) == 1, (cls, kinds)
        assert cls.exit_code == kinds[0].exit_code, cls  # no class picks its own code: its kind does


@pytest.mark.parametrize(("cls", "base"), [
    ("synth.scene.SceneError", ValueError), ("synth.syntax.DslError", ValueError),
    ("synth.config.ConfigError", ValueError), ("frames.rows.FramesError", ValueError),
    ("pipeline.programs.ProgramsError", ValueError), ("synth.scenic.emit.NotGenerated", ValueError),
    ("synth.variants.gibbs.NoVariant", ValueError), ("synth.smt.SolverUnavailable", RuntimeError),
    ("synth.driver.CertificationError", RuntimeError),
])
def test_classes_callers_catch_by_their_builtin_base_keep_it(cls, base):
    module, name = cls.rsplit(".", 1)
    assert issubclass(getattr(importlib.import_module(module), name), base)


def test_the_kinds_mean_what_docs_cli_says():
    assert (InputError.exit_code, CheckFailed.exit_code, SamplingError.exit_code, InternalError.exit_code) == (2, 3, 4, 1)
    from pipeline.variants.sample import SamplingFailed
    from synth.scene import SceneError

    assert SamplingFailed.exit_code == ExitCode.SAMPLING_FAILED and SceneError.exit_code == ExitCode.BAD_INPUT


def test_docs_cli_exit_code_table_lists_exactly_the_named_codes_and_kinds():
    import synth.errors

    text = (ROOT / "docs" / "cli.md").read_text()
    section = text.split("## Exit codes", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| (\d+) \| `(\w+)`(?:: `(\w+)`)?", section, flags=re.M)
    assert [(int(code), name) for code, name, _ in rows] == [(int(c), c.name) for c in sorted(ExitCode)]
    kinds = {name: kind for _, name, kind in rows if kind}
    assert {k: getattr(synth.errors, v).exit_code.name for k, v in kinds.items()} == {k: k for k in kinds}
    assert sorted(kinds.values()) == sorted(k.__name__ for k in KINDS)


def _kind_raiser(kind: type[R2sError]):
    def run(args):
        raise kind("the message")

    return run


@pytest.mark.parametrize("kind", [InputError, CheckFailed, SamplingError])
def test_the_cli_maps_each_kind_to_its_code_with_one_line(kind, monkeypatch, capsys):
    import pipeline.cli

    module = importlib.import_module(pipeline.cli.VERBS["scene"][0])
    monkeypatch.setattr(module, "run", _kind_raiser(kind))
    assert pipeline.cli.main(["scene", "frames.parquet", "f"]) == kind.exit_code
    assert capsys.readouterr().err == "r2s scene: the message\n"


@pytest.mark.parametrize("error", [InternalError("the message"), KeyError("the message")])
def test_an_internal_error_or_a_bug_exits_1_and_r2s_debug_shows_the_traceback(error, monkeypatch, capsys):
    import pipeline.cli

    def run(args):
        raise error

    module = importlib.import_module(pipeline.cli.VERBS["scene"][0])
    monkeypatch.setattr(module, "run", run)
    monkeypatch.delenv("R2S_DEBUG", raising=False)
    assert pipeline.cli.main(["scene", "frames.parquet", "f"]) == ExitCode.INTERNAL_ERROR
    err = capsys.readouterr().err
    assert err.startswith(f"r2s scene: internal error: {type(error).__name__}: ") and err.count("\n") == 1
    monkeypatch.setenv("R2S_DEBUG", "1")
    with pytest.raises(type(error)):
        pipeline.cli.main(["scene", "frames.parquet", "f"])


def test_a_bad_scene_for_synth_exits_2_without_loading_pandas(tmp_path):
    bad = tmp_path / "scene.json"
    bad.write_text('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": "NaN"}]}')
    code = ("import sys; from pipeline.cli import main; code = main(['synth', sys.argv[1]]); "
            "print(code, sorted(m for m in ('pandas', 'pyarrow') if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code, str(bad)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.stdout == "2 []\n", proc.stdout + proc.stderr
    assert proc.stderr.startswith("r2s synth: ") and proc.stderr.count("\n") == 1
