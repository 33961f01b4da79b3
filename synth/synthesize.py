"""ConstraintSolvingBasedSynthesizer (the paper's Alg. 1): one scene in, a minimum-cost program out.

`synthesize` is the Python API's entry point (`from synth import synthesize`, docs/api.md): a Frame through the
one driver (synth.driver). The package exports it under this module's own name, so this module is imported
whenever `synth` is: it loads only the scene, config and result modules, and the core (the driver, DSL, oracles,
solver, search, Scenic) on the first call.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from synth.config import SynthConfig, as_config
from synth.result import SynthResult
from synth.scene import Scene, as_scene


def synthesize(scene: Scene | Mapping[str, Any], config: SynthConfig | Mapping[str, Any] | None = None) -> SynthResult:
    """A minimum-cost program whose semantics contain `scene` (docs/dsl.md).

    `scene`: a Scene, or a decoded scene JSON document (a dict, validated as scene_from_dict validates it).
    `config`: a SynthConfig, a dict of its fields (or {"synth": {...}}, as a TOML file decodes), or None for the
    defaults. Bad input raises SceneError / ConfigError (ValueErrors with one-line messages); with motion, a scene
    entity without a speed raises SpeedMissing; with lanes, a scene without a road (or an entity without lane facts)
    raises LanesMissing. A program the solver cannot certify raises CertificationError (a
    bug, never a silent result). Deterministic: the same scene and config give the same program and Scenic text.
    """
    from synth.driver import Frame, drive  # the core loads on the first call (the module's docstring)

    scene = as_scene(scene)
    config = as_config(config)
    return drive(Frame.of(scene, config), config)
