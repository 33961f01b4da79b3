"""Query patterns (scenario mining): one-frame patterns, DSL programs whose names are variables (`one_frame`), and
temporal patterns, steps of them over time (`temporal`)."""
