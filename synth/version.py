"""The version of r2sgen, which every output names. A module of its own so that the modules of synth can read it
without importing the package (whose __init__ imports them)."""

__version__ = "0.1.0"
