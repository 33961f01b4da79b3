"""`r2s export`: a recorded frame and its variants, back in their source's world, as scenarios simulators replay:
a ScenarioNet database (`scenarionet.py`) or OpenSCENARIO with OpenDRIVE (`openscenario.py`); `stage.py` reads
the inputs one at a time and writes the output staged (docs/cli.md, docs/formats.md "Exported scenarios").
Light: `r2s export --help` reads TARGETS from here."""

TARGETS = ("scenarionet", "openscenario")
