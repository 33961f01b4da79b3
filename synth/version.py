"""The version of r2sgen, which every output names. A module of its own so that the modules of synth can read it
without importing the package (whose __init__ imports them)."""

__version__ = "0.1.0"

# The revision of what synthesis makes of a frame (its program, Scenic text, result fields) within a version. Bump
# it with every change that changes an output for the same input and configuration: `r2s run` keeps a stored row
# only when it was written at this revision of this version (ROWS_VERSION), so a rerun after the change recomputes.
# tests/synth/test_synthesis_revision.py fails when the golden outputs change and this number does not.
SYNTHESIS_REVISION = 1

# What a programs row records as its `version` (docs/formats.md) and a resumed run compares: the release and the
# synthesis revision, as a PEP 440 local version.
ROWS_VERSION = f"{__version__}+synthesis.{SYNTHESIS_REVISION}"
