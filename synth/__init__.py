"""r2sgen's pure core: scenes, the relational DSL, its semantics, relation oracles and the search.

Nothing in this package reads files or datasets; callers hand it values and get values back.
"""

__version__ = "0.1.0"
