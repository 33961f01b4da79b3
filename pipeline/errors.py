"""Errors a user can act on. Anything raised as one of these exits 2 with one line and no traceback."""

from __future__ import annotations


class UserError(Exception):
    """Bad input or usage: exit code 2, one line on stderr."""


def user_error_types() -> tuple[type[BaseException], ...]:
    """Every exception class that means 'bad input' rather than 'bug' (all carry one-line messages)."""
    from extractors.frames import FramesError
    from pipeline.programs import ProgramsError
    from synth.config import ConfigError
    from synth.dsl import DslError
    from synth.scene import SceneError
    from synth.smt import SolverUnavailable

    return (UserError, SceneError, DslError, ConfigError, SolverUnavailable, FramesError, ProgramsError)
