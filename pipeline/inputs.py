"""Reading the small inputs of single-scene verbs: scene JSON, DSL programs, TOML configs."""

from __future__ import annotations

import tomllib
from pathlib import Path

from pipeline.errors import UserError
from synth.config import ConfigError, SynthConfig, config_from_mapping
from synth.scene import DEFAULT_MAX_ENTITIES, Scene, scene_from_json

MAX_TEXT_BYTES = 64 * 1024 * 1024


def read_text_file(path: str, what: str) -> str:
    p = Path(path)
    if not p.exists():
        raise UserError(f"{what} {path} does not exist")
    if p.is_dir():
        raise UserError(f"{what} {path} is a directory, not a file")
    try:
        if p.stat().st_size > MAX_TEXT_BYTES:
            raise UserError(f"{what} {path} is larger than {MAX_TEXT_BYTES // 2**20} MB")
        data = p.read_bytes()
    except OSError as exc:
        raise UserError(f"cannot read {what} {path}: {exc.strerror}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{what} {path} is not UTF-8 text") from None


def read_scene(path: str, max_entities: int | None = None) -> Scene:
    """A scene JSON file, or standard input for "-" (so `r2s scene F ID | r2s render - ...` works)."""
    if path == "-":
        import sys

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


def load_config(path: str | None) -> SynthConfig:
    """configs/default.toml values are the dataclass defaults; a file overrides what it names."""
    if path is None:
        return SynthConfig()
    text = read_text_file(path, "config")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML: {exc}") from None
    try:
        return config_from_mapping(raw)
    except (ConfigError, TypeError) as exc:
        raise UserError(f"{path}: {exc}") from None
