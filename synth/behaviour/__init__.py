"""Behaviour programs of a clip (docs/dsl.md, "Behaviour programs"; issue 38): how each entity moves over
consecutive frames, as segments of a path and a pace with duration Ranges.

One module per job: `track` (a clip's frames as one track per entity), `kinds` (the paths and paces: their
semantics over samples, cost, text, and what synthesis writes), `program` (segments, behaviours, clip programs:
printing and parsing), `segmentation` (the minimum-cost behaviour of a track), `check` (does a clip program hold
of a clip), `synthesize` (a clip to its clip program), `scenic` (a clip program as a dynamic Scenic scenario).
Pure functions and frozen values, no I/O. Importing the package loads nothing but this docstring.
"""
