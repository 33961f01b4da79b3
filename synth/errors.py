"""The one root of every error r2sgen raises, its four kinds, and the exit code each kind means (docs/cli.md).

Every exception class of synth, extractors and pipeline descends from R2sError through exactly one kind; the
kind carries the exit code, so `r2s` maps an error to its code in one place (pipeline.cli) and a new error class
only chooses its kind. Classes that callers catch as ValueError / RuntimeError (SceneError, SolverUnavailable...)
keep that base beside their kind. This module imports nothing, so that synth can use it and the CLI can catch the
root without loading pandas, pyarrow or z3.
"""

from __future__ import annotations

import enum


class ExitCode(enum.IntEnum):
    """What `r2s` exits with (the table of docs/cli.md lists exactly these)."""

    OK = 0
    INTERNAL_ERROR = 1  # a bug: one line on stderr, R2S_DEBUG=1 shows the traceback
    BAD_INPUT = 2  # bad input or usage: one line on stderr, nothing written
    CHECK_FAILED = 3  # r2s check: the program does not contain the scene
    SAMPLING_FAILED = 4  # r2s sample / render --samples: no variant within the budget
    INTERRUPTED = 130  # Ctrl-C (128 + SIGINT)
    TERMINATED = 143  # SIGTERM (128 + SIGTERM)


class R2sError(Exception):
    """The root. Its message is one line, fit for a user; `exit_code` is the kind's."""

    exit_code: ExitCode = ExitCode.INTERNAL_ERROR


class InputError(R2sError):
    """Bad input or usage: a file, a value or an option that is not what it must be."""

    exit_code = ExitCode.BAD_INPUT


class CheckFailed(R2sError):
    """A valid program that does not contain a valid scene (the violations are listed beside it)."""

    exit_code = ExitCode.CHECK_FAILED


class SamplingError(R2sError):
    """A valid program and scene for which no variant was found within the budget (not bad input)."""

    exit_code = ExitCode.SAMPLING_FAILED


class InternalError(R2sError):
    """A bug, or a signal of our own that escaped the code meant to catch it."""

    exit_code = ExitCode.INTERNAL_ERROR


KINDS: tuple[type[R2sError], ...] = (InputError, CheckFailed, SamplingError, InternalError)


def exit_code(exc: BaseException) -> ExitCode:
    """The exit code of an exception: its kind's for ours, INTERNAL_ERROR for anything else (a bug)."""
    return exc.exit_code if isinstance(exc, R2sError) else ExitCode.INTERNAL_ERROR
