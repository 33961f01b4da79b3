"""The errors of the pipeline: synth.errors' root, kinds and exit codes (one house for every package), and
UserError, the pipeline's own bad input (a path, an option, a file that is not ours)."""

from __future__ import annotations

from synth.errors import (  # noqa: F401 (re-exported: the pipeline's code and its users import them from here)
    KINDS,
    CheckFailed,
    ExitCode,
    InputError,
    InternalError,
    R2sError,
    SamplingError,
    exit_code,
)


class UserError(InputError):
    """Bad input or usage met by a verb or the batch stage: exit code 2, one line on stderr."""
