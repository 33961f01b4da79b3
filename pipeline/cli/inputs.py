"""Reading the small inputs of single-scene verbs: scene JSON, DSL programs, TOML configs."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

from pipeline.errors import UserError
from storage.regular_files import FileTooLarge, NotRegularFile, read_regular
from synth.config import ConfigError, SynthConfig, config_from_mapping
from synth.scene import DEFAULT_MAX_ENTITIES, Scene, scene_from_json

MAX_TEXT_BYTES = 64 * 1024 * 1024


def read_text_file(path: str, what: str) -> str:
    """A small UTF-8 text input (scene, program, pattern, config, Scenic): a regular file (storage.regular_files:
    never a FIFO or a device, read at most MAX_TEXT_BYTES + 1 bytes)."""
    p = Path(path)
    if not p.exists():
        raise UserError(f"{what} {path} does not exist")
    try:
        data = read_regular(p, MAX_TEXT_BYTES)
    except FileTooLarge:
        raise UserError(f"{what} {path} is larger than {MAX_TEXT_BYTES // 2**20} MB") from None
    except NotRegularFile as exc:
        raise UserError(f"{what} {path} {exc.strerror}") from None
    except OSError as exc:
        raise UserError(f"cannot read {what} {path}: {exc.strerror}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{what} {path} is not UTF-8 text") from None


def read_program(path: str):
    """A DSL program file (r2s check, and the --program of r2s sample and r2s render)."""
    from synth.dsl import DslError, parse_program  # python-flint: r2s export reads scene JSON only

    try:
        return parse_program(read_text_file(path, "program"))
    except DslError as exc:
        raise UserError(f"{path}: {exc}") from None


def read_pattern(path: str):
    """A pattern file (r2s query, r2s report --query): DSL statements whose names are variables, or a temporal
    pattern (steps, durations, behaviours: synth.patterns.temporal)."""
    from synth.dsl import DslError
    from synth.patterns.temporal import parse_query_pattern

    try:
        return parse_query_pattern(read_text_file(path, "pattern"))
    except DslError as exc:
        raise UserError(f"{path}: {exc}") from None


def read_scene(path: str, max_entities: int | None = None) -> Scene:
    """A scene JSON file, or standard input for "-" (so `r2s scene F ID | r2s render - ...` works)."""
    if path == "-":
        text = sys.stdin.read(MAX_TEXT_BYTES + 1)
        if len(text) > MAX_TEXT_BYTES:
            raise UserError(f"the scene on standard input is larger than {MAX_TEXT_BYTES // 2**20} MB")
        path = "standard input"
    else:
        text = read_text_file(path, "scene")
    try:
        return scene_from_json(text, max_entities=max_entities or DEFAULT_MAX_ENTITIES)
    except ValueError as exc:
        raise UserError(f"{path}: {exc}") from None


def preset_names() -> list[str]:
    """The configuration presets shipped as package data (configs/*.toml): what `--config NAME` accepts."""
    from importlib.resources import files

    return sorted(f.name[: -len(".toml")] for f in files("configs").iterdir() if f.name.endswith(".toml"))


def _preset_text(name: str) -> str | None:
    from importlib.resources import files

    return files("configs").joinpath(f"{name}.toml").read_text("utf-8") if name in preset_names() else None


def load_config(path: str | None) -> SynthConfig:
    """`--config`: a preset name (`default`, `paper`: configs/*.toml, shipped with the package) or a TOML file (a
    path; a file wins over a preset of the same name). configs/default.toml values are the dataclass defaults; a
    file overrides what it names."""
    if path is None:
        return SynthConfig()
    text = None if Path(path).exists() else _preset_text(path)
    if text is None and not Path(path).exists() and "/" not in path and not path.endswith(".toml"):
        import difflib

        names = preset_names()
        close = difflib.get_close_matches(path, names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise UserError(f"config {path!r} is neither a file nor a preset (presets: {', '.join(names)}){hint}")
    if text is None:
        text = read_text_file(path, "config")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML: {exc}") from None
    try:
        return config_from_mapping(raw)
    except (ConfigError, TypeError) as exc:
        raise UserError(f"{path}: {exc}") from None
