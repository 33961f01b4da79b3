"""r2sgen's pure core: scenes, the relational DSL, its semantics, relation oracles and the search.

Nothing in this package reads files or datasets; callers hand it values and get values back. The Python API
(docs/api.md):

    from synth import synthesize, check
    scene = {"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
                                           {"id": "car1", "type": "Car", "x": 0, "y": 8, "heading": 0}]}
    result = synthesize(scene)
    print(result.program)                  # car1 = new Car ahead of ego by Range(5.5, 10.5), facing away from ego
    check(result.program, scene).ok        # True: the program contains the scene
    synthesize_window([scene, scene2])     # one program for consecutive frames of a scene (synth.window.program)

Importing the package loads only the scene and configuration modules; the DSL, the oracles, the solver and the
search load on first use (`Program`, `parse_program`, `check` by name, the rest inside synthesize).
"""

import importlib

# synthesize shares its name with its module, which every import of that module would bind here (the import
# system sets the attribute after loading a submodule): importing the module now binds the function for good.
from synth.config import ConfigError, SynthConfig  # noqa: E402
from synth.errors import ExitCode, InputError, R2sError  # noqa: E402
from synth.result import SynthResult, SynthStats  # noqa: E402
from synth.scene import Entity, Scene, SceneError, scene_from_dict, scene_from_json  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402
from synth.version import __version__  # noqa: E402, F401

# Loaded on first access: the DSL needs the statement parts (numpy, the interval library), its syntax fractions.
_LAZY = {
    "DslError": "synth.syntax",
    "Program": "synth.dsl",
    "parse_program": "synth.dsl",
    "check": "synth.semantics",
    "CheckResult": "synth.semantics",
    "synthesize_window": "synth.window.program",
    "check_window": "synth.window.program",
    "frame_program": "synth.window.program",
    "tile": "synth.window.program",
    "WindowResult": "synth.window.program",
    "WindowError": "synth.window.program",
    "synthesize_behaviours": "synth.behaviour.synthesize",
    "ClipResult": "synth.behaviour.synthesize",
    "check_clip": "synth.behaviour.check",
    "parse_clip_program": "synth.behaviour.program",
}

__all__ = [
    "CheckResult", "ClipResult", "ConfigError", "DslError", "Entity", "ExitCode", "InputError", "Program", "R2sError",
    "Scene", "SceneError", "SynthConfig", "SynthResult", "SynthStats", "WindowError", "WindowResult", "check",
    "check_clip", "check_window", "frame_program", "parse_clip_program", "parse_program", "scene_from_dict",
    "scene_from_json", "synthesize", "synthesize_behaviours", "synthesize_window", "tile",
]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'synth' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
