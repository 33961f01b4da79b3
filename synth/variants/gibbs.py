"""Variants of a recorded scene: Metropolis-within-Gibbs over a program's random parameters.

The distribution is Scenic's for the emitted text (synth.scenic.emit): every Range of the program drawn
uniformly in Scenic's own parameterisation (synth.variants.parameters), conditioned on the collision rule
(synth.variants.collision_rule: two boxes may overlap only if they overlap in the recording). Scenic draws it by
rejecting whole scenes, which fails exponentially in the number of entities; this chain changes one statement
part at a time instead:

- a move redraws one clause's parameters uniformly from their box (the prior) and re-evaluates the entity and
  everything that depends on it, as the program says (a reference that moves carries its dependants along,
  Parameterisation.moved_by), and is kept if no box it moved now overlaps a box it may not overlap. The target
  density is constant on the allowed set and the first draw does not depend on the current value, so this is
  Metropolis-Hastings with the prior as proposal. On a rejection the box shrinks toward the current value and
  the clause is drawn again (Neal's hyperrectangle shrinkage for slice sampling, up to MAX_DRAWS draws): each
  draw's transition is symmetric, so the target stays invariant, and a clause boxed in by its neighbours still
  moves a little instead of being stuck;
- a re-anchoring move then moves the entity alone: a random-walk step in the same clause, with the clauses
  that read it re-expressed so that the entities that refer to it stay where they are, accepted with the
  Jacobian of that re-expression (Draws.area) if every re-expressed parameter stays in its box and the rule
  holds. Without it a reference with a large subtree (a row of barriers placed one after another) mixes only
  as fast as the whole subtree can move at once (at 141 entities it shortens the slowest autocorrelation times
  two- to fivefold, bench/results/variants.md);
- a sweep moves every clause of every statement once, in declaration order;
- the chain starts at the recorded scene, whose parameters are read back exactly (Parameterisation.start):
  the program contains the scene, and the rule holds there by definition. It then runs `burn_in` sweeps and
  keeps a variant every `thin` sweeps (defaults from the autocorrelation measured in bench/bench_variants.py).

If the given scene is not a valid start (a program that does not contain it), the chain first descends to a
state that satisfies the rule (moves accepted when they do not add violations), and gives up after
`start_sweeps` sweeps with NoVariant naming the pairs that still collide. Without a rule (collisions allowed)
every draw is accepted, there is no re-anchoring, and each sweep is an exact independent draw from the program.

Pure and deterministic: numpy's PCG64 seeded with the seed, no I/O, no global state; variant k depends only on
the program, the scene, the tolerances, the settings and the seed (never on how many variants are asked for).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from synth.config import DEFAULT_BURN_IN, DEFAULT_THIN, SynthConfig
from synth.dsl import Program
from synth.errors import SamplingError
from synth.scene import Entity, Scene, make_scene
from synth.variants.collision_rule import CollisionRule, collision_rule
from synth.variants.overlap import box_radius, boxes_overlap
from synth.variants.parameters import SPEED, Parameterisation, Pose, inside, parameterise
from synth.variants.scene_road import SceneRoad

DEFAULT_START_SWEEPS = 200  # sweeps to find a valid start when the given scene is not one
MAX_DRAWS = 8  # draws per move: the first from the whole box, each next from a box shrunk after a rejection
REANCHOR_SCALES = (0.02, 0.1, 0.5)  # random-walk steps of a re-anchoring move, as shares of the box (a mixture)
FEW_PAIRS = 24  # up to this many candidate pairs are tested one by one in floats (numpy's per-call cost dominates)


@dataclass(frozen=True)
class ChainSettings:
    burn_in: int = DEFAULT_BURN_IN
    thin: int = DEFAULT_THIN
    start_sweeps: int = DEFAULT_START_SWEEPS

    def __post_init__(self) -> None:
        if self.burn_in < 0 or self.thin < 1 or self.start_sweeps < 0:
            raise ValueError("burn_in and start_sweeps must be >= 0 and thin >= 1")


@dataclass(frozen=True)
class ChainStats:
    sweeps: int  # after the start was found
    start_sweeps: int  # spent finding a valid start (0: the given scene was one)
    proposals: int
    accepted: int
    frozen: tuple[str, ...]  # entities none of whose parts ever moved (their variants all equal the start)

    @property
    def acceptance(self) -> float:
        return self.accepted / self.proposals if self.proposals else 1.0


@dataclass(frozen=True)
class Variants:
    scenes: tuple[Scene, ...]
    stats: ChainStats


class NoVariant(SamplingError, ValueError):
    """No state satisfies the program and the collision rule within the budget. Names the colliding pairs."""

    def __init__(self, message: str, pairs: tuple[tuple[str, str], ...]):
        super().__init__(message)
        self.pairs = pairs


class Chain:
    """The Markov chain over a program's parameters; `sweep()` advances it, `scene()` reads the state."""

    def __init__(self, program: Program, scene: Scene, config: SynthConfig, seed: int,
                 allow_collisions: bool = False):
        self.params_of: Parameterisation = parameterise(program, scene, config)
        p = self.params_of
        self.rule: CollisionRule | None = None if allow_collisions else collision_rule(program, scene, config, p)
        self.rng = np.random.Generator(np.random.PCG64(seed))
        self.frame_id = scene.frame_id
        # The recorded road, for the requirements that keep an entity in its regions (a lane clause) and the lane
        # facts every variant carries; None for a scene without one.
        self.road = SceneRoad(scene.road) if scene.road is not None else None
        self.poses, self.params = p.start(scene)
        n = len(p.ids)
        by_id = scene.by_id()
        dims = [by_id[i].dimensions() for i in p.ids]
        self.length = np.array([d[0] for d in dims])
        self.width = np.array([d[1] for d in dims])
        self.lengths, self.widths = self.length.tolist(), self.width.tolist()
        self.radius = box_radius(self.length, self.width)
        self.x = np.array([q.x for q in self.poses])
        self.y = np.array([q.y for q in self.poses])
        self.h = np.array([q.heading for q in self.poses])
        # forbid[i, j]: i and j may not overlap (they do not in the recording); nothing is forbidden without a rule.
        self.forbid = np.zeros((n, n), dtype=bool)
        if self.rule is not None:
            self.forbid[:] = True
            np.fill_diagonal(self.forbid, False)
            for i, j in self.rule.recorded:
                self.forbid[i, j] = self.forbid[j, i] = False
        # dependants[k]: every entity whose value follows k's through some chain of references, in order.
        self.dependants: list[list[int]] = [[] for _ in range(n)]
        for k in range(n - 1, 0, -1):  # a reference comes before its dependants: theirs are complete here
            for r in {r for r in p.refs[k] if r is not None}:
                self.dependants[r] = sorted(set(self.dependants[r]) | {k} | set(self.dependants[k]))
        # moves[k][part]: the entities a redraw of that part changes, k first (a heading move leaves alone those
        # that only face k, a position move those that only turn with k).
        changes = [[p.moved_by(k, j, self.dependants[k]) for j in range(len(p.draws[k]))] for k in range(n)]
        self.moves = [[np.array(moved) for moved, _ in row] for row in changes]
        # Does a redraw of that clause move any box? (A speed alone does not: no collision test.)
        self.geometric = [[bool(fields - {SPEED}) for _, fields in row] for row in changes]
        # required[m]: m's clauses with a requirement beyond their box (Draws.allowed).
        self.required = [[c for c, d in enumerate(p.draws[m]) if d.requires] for m in range(n)]
        self.motion = any(d.writes == SPEED for row in p.draws for d in row)
        self.readers = [[self._readers(k, j) for j in range(len(p.draws[k]))] for k in range(n)]
        self.proposals = self.accepted = 0
        self.moved = np.zeros(n, dtype=bool)
        self.moved[0] = True

    # -------------------------------------------------------------------------------------- the rule

    def _violations(self, idx: np.ndarray, x: np.ndarray, y: np.ndarray, h: np.ndarray) -> int:
        """How many forbidden pairs with at least one end in idx overlap at (x, y, h) (a pair inside idx twice)."""
        if self.rule is None:
            return 0
        dx, dy, reach = x[idx][:, None] - x, y[idx][:, None] - y, self.radius[idx][:, None] + self.radius
        a, b = np.nonzero((dx * dx + dy * dy <= reach * reach) & self.forbid[idx])
        if a.size == 0:
            return 0
        a = idx[a]
        if a.size > FEW_PAIRS:
            return int(np.count_nonzero(boxes_overlap(x[a], y[a], h[a], self.length[a], self.width[a],
                                                      x[b], y[b], h[b], self.length[b], self.width[b])))
        xs, ys, hs, ls, ws = x.tolist(), y.tolist(), h.tolist(), self.lengths, self.widths
        return sum(boxes_overlap(xs[i], ys[i], hs[i], ls[i], ws[i], xs[j], ys[j], hs[j], ls[j], ws[j], xp=math)
                   for i, j in zip(a.tolist(), b.tolist()))

    def violated_pairs(self) -> list[tuple[int, int]]:
        """Forbidden pairs (i < j) that overlap in the current state."""
        if self.rule is None:
            return []
        x, y, h = self.x, self.y, self.h
        i, j = np.nonzero(np.triu(self.forbid, 1) & (np.hypot(x[:, None] - x, y[:, None] - y)
                                                      <= self.radius[:, None] + self.radius))
        hit = boxes_overlap(x[i], y[i], h[i], self.length[i], self.width[i], x[j], y[j], h[j],
                            self.length[j], self.width[j])
        return [(int(a), int(b)) for a, b in zip(i[hit], j[hit])]

    # -------------------------------------------------------------------------------------- moves

    def _move(self, k: int, part: int, descend: bool) -> None:
        """Redraw one part's parameters: uniformly in its box, shrunk toward the current value on each rejection."""
        p = self.params_of
        lo, hi = list(p.draws[k][part].lo), list(p.draws[k][part].hi)
        now = self.params[k][part]
        idx = self.moves[k][part]
        moved = idx.tolist()
        before = self._unmet(moved, self.poses) + self._violations(idx, self.x, self.y, self.h) if descend else 0
        for _ in range(1 if descend else MAX_DRAWS):
            new = tuple(a + (b - a) * t for a, b, t in zip(lo, hi, self.rng.random(len(lo))))
            row = list(self.params[k])
            row[part] = new
            trial = list(self.poses)
            trial[k] = Pose()
            p.evaluate_into(k, row, trial)
            x, y, h = self.x.copy(), self.y.copy(), self.h.copy()
            x[k], y[k], h[k] = trial[k].x, trial[k].y, trial[k].heading
            self.proposals += 1
            for m in moved[1:]:
                trial[m] = Pose()
                p.evaluate_into(m, self.params[m], trial)
                x[m], y[m], h[m] = trial[m].x, trial[m].y, trial[m].heading
            after = self._unmet(moved, trial) + (self._violations(idx, x, y, h) if self.geometric[k][part] else 0)
            if not after or (descend and after <= before):
                self.accepted += 1
                self.moved[k] = True
                self.poses, self.x, self.y, self.h = trial, x, y, h
                self.params[k] = row
                return
            # Neal's hyperrectangle shrinkage: the box keeps the current value and loses the rejected side.
            for d, (v, c) in enumerate(zip(new, now)):
                if v < c:
                    lo[d] = v
                else:
                    hi[d] = v

    def _unmet(self, moved, poses: list[Pose]) -> int:
        """How many requirements beyond the boxes (Draws.allowed) the moved entities' clauses fail at poses."""
        p = self.params_of
        return sum(not p.draws[m][c].allowed(poses[m], _at(poses, p.refs[m][c]), self.road)
                   for m in moved for c in self.required[m])

    def unmet_entities(self) -> list[str]:
        """The entities some requirement of whose clauses fails in the current state."""
        p = self.params_of
        return [p.ids[m] for m in range(1, len(self.poses)) if self._unmet([m], self.poses)]

    def _readers(self, k: int, part: int) -> list[tuple[int, int]]:
        """(m, clause) of the other entities whose clauses read what a redraw of k's clause `part` changes."""
        p = self.params_of
        changed = {p.draws[k][part].writes}
        for c in range(part + 1, len(p.draws[k])):
            if changed & set(p.draws[k][c].reads_own):
                changed.add(p.draws[k][c].writes)
        return [(m, c) for m in self.dependants[k] for c, (d, r) in enumerate(zip(p.draws[m], p.refs[m]))
                if r == k and changed & set(d.reads)]

    def _reanchor(self, k: int, part: int) -> None:
        """Move k alone: a random-walk step in one of its clauses, its readers' parameters re-expressed so that
        they stay where they are. Metropolis-Hastings with the Jacobian of that re-expression (Draws.area):
        accepted with probability min(1, prod area(old) / area(new)) if every re-expressed parameter stays in its
        box and k's box keeps the rule. Lets a reference move without carrying its whole subtree along."""
        p = self.params_of
        draws = p.draws[k][part]
        scale = REANCHOR_SCALES[int(self.rng.integers(len(REANCHOR_SCALES)))]
        steps = self.rng.random(len(draws.lo))
        new = tuple(_reflect(v + scale * (b - a) * (2 * t - 1), a, b)
                    for v, a, b, t in zip(self.params[k][part], draws.lo, draws.hi, steps))
        row = list(self.params[k])
        row[part] = new
        trial = list(self.poses)
        trial[k] = Pose()
        p.evaluate_into(k, row, trial)
        self.proposals += 1
        weight, updates = 1.0, []
        for m, c in self.readers[k][part]:
            d = p.draws[m][c]
            value = d.invert(self.poses[m], trial[k])
            if not inside(d, value) or d.area(value, trial[k]) <= 0.0:
                return
            weight *= d.area(self.params[m][c], self.poses[k]) / d.area(value, trial[k])
            updates.append((m, c, value))
        if weight < 1.0 and self.rng.random() >= weight:
            return
        if self._unmet([k, *(m for m, _, _ in updates)], trial):
            return
        x, y, h = self.x.copy(), self.y.copy(), self.h.copy()
        x[k], y[k], h[k] = trial[k].x, trial[k].y, trial[k].heading
        if self.geometric[k][part] and self._violations(np.array([k]), x, y, h):
            return
        self.accepted += 1
        self.moved[k] = True
        self.poses, self.x, self.y, self.h = trial, x, y, h
        self.params[k] = row
        for m, c, value in updates:
            self.params[m] = [*self.params[m][:c], value, *self.params[m][c + 1:]]

    def sweep(self, descend: bool = False) -> None:
        """Move every part of every statement once, in declaration order (and re-anchor it, where it is read)."""
        for k in range(1, len(self.poses)):
            for part, draws in enumerate(self.params_of.draws[k]):
                if not draws.lo:
                    continue  # a Requirement draws nothing: the moves of what it reads ask it
                self._move(k, part, descend)
                if not descend and self.rule is not None and self.readers[k][part]:  # without a rule, no need
                    self._reanchor(k, part)

    def draw_from_prior(self) -> None:
        """Every parameter drawn afresh from its box, the rule ignored: one of Scenic's rejection proposals."""
        p = self.params_of
        for k in range(1, len(self.poses)):
            self.params[k] = [tuple(a + (b - a) * t for a, b, t in zip(part.lo, part.hi, self.rng.random(len(part.lo))))
                              for part in p.draws[k]]
            p.evaluate_into(k, self.params[k], self.poses)
        self.x = np.array([q.x for q in self.poses])
        self.y = np.array([q.y for q in self.poses])
        self.h = np.array([q.heading for q in self.poses])

    # -------------------------------------------------------------------------------------- reading

    def parameters(self) -> np.ndarray:
        """The current parameters, flat, in declaration order (part by part)."""
        return np.array([v for row in self.params[1:] for part in row for v in part])

    def scene(self, frame_id: str) -> Scene:
        p = self.params_of
        # With motion every entity has a speed (0 without a motion clause, as Scenic's default), else none.
        ents = [Entity(i, t, float(q.x) + 0.0, float(q.y) + 0.0, float(q.heading) + 0.0, float(length), float(width),
                       speed=float(q.speed) + 0.0 if self.motion else None)
                for i, t, q, length, width in zip(p.ids, p.types, self.poses, self.length, self.width)]
        scene = make_scene(frame_id, ents)
        return scene if self.road is None else self.road.placed(scene)


def sample_variants(program: Program, scene: Scene, config: SynthConfig, n: int, seed: int,
                    settings: ChainSettings = ChainSettings(), allow_collisions: bool = False,
                    progress: Callable[[int, int], None] | None = None) -> Variants:
    """n variants of `scene` from `program` (the scene's program, or any program declaring entities of it)."""
    chain = Chain(program, scene, config, seed, allow_collisions)
    start = 0
    everyone = range(1, len(chain.poses))
    while chain.violated_pairs() or chain._unmet(everyone, chain.poses):
        if start == settings.start_sweeps:
            pairs = tuple(chain.rule.named(tuple(chain.violated_pairs()))) if chain.rule else ()
            if not pairs:  # only requirements beyond the boxes fail (a speed below a Range, a lane clause)
                raise NoVariant(f"no variant found in {start} sweeps: the requirements of "
                                f"{', '.join(chain.unmet_entities())} never hold (a reference never fast enough for "
                                "a relative speed below it, or an entity never in the regions its lane clause "
                                "names)", ())
            shown = ", ".join(f"{a} and {b}" for a, b in pairs[:5])
            raise NoVariant(f"no variant found in {start} sweeps: {len(pairs)} pair{'s' if len(pairs) > 1 else ''} "
                            f"of boxes that do not overlap in the scene always collide ({shown}"
                            f"{', ...' if len(pairs) > 5 else ''})", pairs)
        chain.sweep(descend=True)
        start += 1
    total = settings.burn_in + (n - 1) * settings.thin + 1
    scenes = []
    for s in range(1, total + 1):
        chain.sweep()
        if progress is not None:
            progress(s, total)
        if s > settings.burn_in and (s - settings.burn_in - 1) % settings.thin == 0:
            scenes.append(chain.scene(f"{scene.frame_id[:240]}#sample{len(scenes)}"))
    frozen = tuple(i for i, m in zip(chain.params_of.ids[1:], chain.moved[1:]) if not m)
    return Variants(tuple(scenes), ChainStats(total, start, chain.proposals, chain.accepted, frozen))


@dataclass(frozen=True)
class RejectionOdds:
    draws: int
    clear: int  # draws that satisfy the rule: what whole-scene rejection would accept
    pairs: tuple[tuple[tuple[str, str], float], ...]  # colliding pairs, most frequent first, with their share


def rejection_odds(program: Program, scene: Scene, config: SynthConfig, seed: int, draws: int) -> RejectionOdds:
    """How often independent draws from the program satisfy the collision rule, and which pairs collide."""
    chain = Chain(program, scene, config, seed)
    counts: dict[tuple[int, int], int] = {}
    clear = 0
    for _ in range(draws):
        chain.draw_from_prior()
        hits = chain.violated_pairs()
        clear += not hits
        for pair in hits:
            counts[pair] = counts.get(pair, 0) + 1
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    ids = chain.params_of.ids
    return RejectionOdds(draws, clear, tuple(((ids[i], ids[j]), c / draws) for (i, j), c in ranked))


def autocorrelation_time(trace: np.ndarray, window: float = 5.0) -> float:
    """Integrated autocorrelation time of a scalar trace, in steps (1 = independent draws), by Sokal's adaptive
    window: tau = 1 + 2 sum_{t=1..M} rho(t) for the smallest M >= window * tau. NaN for a constant trace."""
    x = np.asarray(trace, dtype=float) - np.mean(trace)
    n = len(x)
    if n < 2 or not np.any(x):
        return float("nan")
    f = np.fft.rfft(x, 2 * n)
    rho = np.fft.irfft(f * np.conj(f))[:n]
    rho = rho / rho[0]
    taus = 1.0 + 2.0 * np.cumsum(rho[1:])
    m = np.arange(1, n)
    ok = np.nonzero(m >= window * taus)[0]
    return float(taus[ok[0]] if ok.size else taus[-1])


def _at(poses: list[Pose], ref: int | None) -> Pose | None:
    return None if ref is None else poses[ref]


def _reflect(v: float, lo: float, hi: float) -> float:
    """v folded back into [lo, hi] at its edges (a symmetric random walk stays symmetric)."""
    if hi <= lo:
        return lo
    while v < lo or v > hi:
        v = 2 * lo - v if v < lo else 2 * hi - v
    return v
