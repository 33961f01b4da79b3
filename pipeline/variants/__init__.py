"""Variants of a recorded scene: sampling them from its program (sample, for `r2s sample` and `r2s render
--samples`) and drawing a scene, its program's references and its variants from above (render; the verb's
gathering of program and variants: picture). `pipeline.sample` and `pipeline.render` are the Python API of `r2s sample`
and `r2s render` (docs/api.md)."""

# Sampling's limits and choices, here (not in sample.py, which loads the DSL and numpy) so that `r2s sample --help`
# and `r2s render --help` show them without loading the sampler.
DEFAULT_MAX_ITERATIONS = 2000  # Scenic's own default for one scene
MAX_SEED = 2**32 - 1  # numpy's seed range
SAMPLERS = ("gibbs", "scenic")

