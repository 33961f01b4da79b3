"""`r2s export`: a recorded frame and its variants, back in their source's world, as scenarios simulators replay:
a ScenarioNet database (`scenarionet.py`) or OpenSCENARIO with OpenDRIVE (`openscenario.py`), or the road alone
as OpenDRIVE (`opendrive.py`); `stage.py` reads
the inputs one at a time and writes the output staged (docs/cli.md, docs/formats.md "Exported scenarios").
Light: `r2s export --help` reads TARGETS from here."""

import re

TARGETS = ("scenarionet", "openscenario")  # the targets that write a folder of scenarios
ROAD_ONLY = "opendrive"  # --to opendrive: the road alone, one .xodr file (pipeline/export/opendrive.py)
FRAMES = ("world", "ego")  # --frame: the source's world, recentred; a scene's ego frame (its Scenic text's)


def slug(text: str) -> str:
    """A frame id as a file-name part (scenario and file names): each run of characters other than letters,
    digits, '.' and '-' as one '_', and none of '.', '-', '_' first (a name starting with '.' is hidden, one
    starting with '-' reads as an option) nor '_' last."""
    return re.sub(r"[^A-Za-z0-9.-]+", "_", text).lstrip("._-").rstrip("_") or "scene"
