"""Does the chain (synth.variants.gibbs) draw Scenic's distribution? Shared by tests/synth/variants/test_variants.py and
bench/bench_variants.py.

Two-sample Kolmogorov-Smirnov tests, one per marginal: every Range parameter (read back from the placed scenes
with the program's parameterisation) and every pairwise centre distance, N_DRAWS draws a side, Scenic's own
rejection sampler against the chain thinned by twice its largest measured integrated autocorrelation time (so its
draws are near independent, as the test assumes). The familywise level is ALPHA, Bonferroni over the m marginals
of a frame. Power: with 400 draws a side and m <= 60 the test rejects as soon as one marginal's CDFs differ by
more than about 0.15 (the asymptotic Kolmogorov critical value, `ks_critical`); tests/synth/variants/test_variants.py checks
that two plausible bugs are caught (a sector half-width of half what the program says; the collision rule
ignored where it binds).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.scene import scene_from_dict
from synth.variants.gibbs import Chain, ChainSettings, autocorrelation_time, sample_variants
from synth.variants.parameters import parameterise

N_DRAWS = 400
ALPHA = 0.01
PILOT_SWEEPS = 300

# Pedestrians in a cluster around ped1 and a car across its path: about half of the program's scenes overlap two
# boxes that are apart in the recording, so the rule shapes the distribution.
TIGHT = scene_from_dict({"frame_id": "tight", "entities": [
    {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
    {"id": "ped1", "type": "Pedestrian", "x": 0, "y": 6, "heading": 0},
    {"id": "ped2", "type": "Pedestrian", "x": -1.5, "y": 6, "heading": 270},
    {"id": "ped3", "type": "Pedestrian", "x": 1.5, "y": 6, "heading": 270},
    {"id": "ped4", "type": "Pedestrian", "x": -3, "y": 6, "heading": 270},
    {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 90}]})
TIGHT_PROGRAM = parse_program(
    "ped1 = new Pedestrian ahead of ego by Range(4, 9), facing Range(-10, 10) deg relative to ego\n"
    "ped2 = new Pedestrian left of ped1 by Range(0, 2.5), facing toward ped1\n"
    "ped3 = new Pedestrian right of ped1 by Range(0, 2.5), facing away from ped1\n"
    "ped4 = new Pedestrian behind ped2 by Range(0, 2.5), facing Range(-5, 5) deg relative to ped2\n"
    "car1 = new Car ahead of ped1 by Range(1, 6), facing Range(85, 95) deg relative to ego\n")


def ks_critical(n: int, alpha: float) -> float:
    """The two-sample KS statistic (n a side) above which a single test rejects at level alpha."""
    from scipy.special import kolmogi

    return float(kolmogi(alpha) * math.sqrt(2.0 / n))


def marginals(program, scenes, config) -> np.ndarray:
    """Per scene: every Range parameter (read back from the placed scene) and every pairwise centre distance."""
    p = parameterise(program, scenes[0], config)
    rows = []
    for s in scenes:
        _, params = p.start(s)
        pts = [(e.x, e.y) for e in s.entities]
        rows.append([v for row in params for part in row for v in part]
                    + [math.dist(a, b) for a, b in itertools.combinations(pts, 2)])
    return np.array(rows)


def autocorrelation_times(program, scene, config, sweeps: int = PILOT_SWEEPS, seed: int = 99) -> np.ndarray:
    """Integrated autocorrelation time (in sweeps) of every parameter over a run from the recorded scene (its
    first tenth dropped as burn-in); NaN for a parameter that never moves."""
    chain = Chain(program, scene, config, seed=seed)
    trace = []
    for _ in range(sweeps):
        chain.sweep()
        trace.append(chain.parameters())
    trace = np.array(trace)[sweeps // 10:]
    return np.array([autocorrelation_time(trace[:, j]) for j in range(trace.shape[1])])


def thinning(program, scene, config) -> tuple[int, float]:
    """(thin, tau): twice the largest autocorrelation time of a pilot run, and that time."""
    taus = autocorrelation_times(program, scene, config)
    tau = float(np.nanmax(taus)) if np.any(~np.isnan(taus)) else 1.0
    return max(1, math.ceil(2 * tau)), tau


def scenic_draws(program, scene, config, n: int = N_DRAWS, seed: int = 1):
    """n scenes from Scenic's own rejection sampler, and its iterations."""
    from pipeline.variants.sample import SampleOptions, sample_program

    drawn = sample_program(program, scene, config, SampleOptions(n=n, seed=seed, sampler="scenic"))
    return drawn.scenes, drawn.iterations


@dataclass(frozen=True)
class Comparison:
    pvalues: np.ndarray  # one per marginal: the parameters, then the pairwise distances
    thin: int
    tau: float

    @property
    def m(self) -> int:
        return len(self.pvalues)

    @property
    def threshold(self) -> float:
        return ALPHA / self.m

    @property
    def same(self) -> bool:
        return bool(self.pvalues.min() > self.threshold)


def compare(program, scene, config, reference, chain_config: SynthConfig | None = None,
            allow_collisions: bool = False, seed: int = 2) -> Comparison:
    """KS p-values of the chain's draws (with chain_config, allow_collisions) against Scenic's `reference`."""
    from scipy.stats import ks_2samp

    chain_config = chain_config or config
    thin, tau = thinning(program, scene, chain_config)
    ours = sample_variants(program, scene, chain_config, len(reference), seed=seed, allow_collisions=allow_collisions,
                           settings=ChainSettings(burn_in=max(20, 5 * thin), thin=thin)).scenes
    a, b = marginals(program, reference, config), marginals(program, ours, config)
    return Comparison(np.array([ks_2samp(a[:, j], b[:, j]).pvalue for j in range(a.shape[1])]), thin, tau)
