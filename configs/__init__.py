"""Configuration presets, shipped with the package as data: `--config NAME` reads `NAME.toml` from this folder.

default.toml spells out the defaults (what SynthConfig uses without --config); paper.toml is the paper's exact
setup. A preset is a [synth] table of config keys (docs/formats.md, "Config TOML"); pipeline.cli.inputs resolves names.
"""
