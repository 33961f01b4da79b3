"""Errors a user can act on. Anything raised as one of these exits 2 with one line and no traceback."""

from __future__ import annotations


class UserError(Exception):
    """Bad input or usage: exit code 2, one line on stderr."""


def user_error_types() -> tuple[type[BaseException], ...]:
    """Every exception class that means 'bad input' rather than 'bug' (all carry one-line messages).

    The frames and programs errors live beside pandas / pyarrow readers; a verb that never imported those
    modules cannot have raised them, so they are only looked up when loaded (a bad scene given to `r2s synth`
    must not pay ~0.4 s of pandas imports to print its one line).
    """
    import sys

    from synth.config import ConfigError
    from synth.dsl import DslError
    from synth.scene import SceneError
    from synth.smt import SolverUnavailable

    types: list[type[BaseException]] = [UserError, SceneError, DslError, ConfigError, SolverUnavailable]
    for module, name in (("extractors.frames", "FramesError"), ("pipeline.programs", "ProgramsError")):
        if module in sys.modules:
            types.append(getattr(sys.modules[module], name))
    return tuple(types)
