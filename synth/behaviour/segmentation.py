"""The minimum-cost behaviour of a track (docs/dsl.md, "Behaviour programs", what synthesis writes): exact dynamic
programming over the boundary samples. Every interval a .. b (a < b) is decided once, folding its samples into a
Summary from a, so the O(n^2) intervals cost O(n^2) folds; best[a] is the cheapest way to cover a .. n-1, and of
equal costs the one with the longest first segment (the largest b)."""

from __future__ import annotations

from dataclasses import dataclass

from synth.behaviour.kinds import Stopped, Summary, outward, pace_possible, write_pace, write_path
from synth.behaviour.program import Behaviour, Segment
from synth.behaviour.track import Track
from synth.config import SynthConfig


def written_segment(m: Summary, config: SynthConfig) -> Segment | None:
    """The segment synthesis writes on an interval summarised by m: its pace, its path (none when stopped), its
    duration's Range; None when no pace or no path can be written."""
    pace = write_pace(m, config)
    if pace is None:
        return None
    path = None if isinstance(pace, Stopped) else write_path(m, config)
    if path is None and not isinstance(pace, Stopped):
        return None
    return Segment(path, pace, outward(max(m.t1 - m.t0, 0.0), max(m.t1 - m.t0, 0.0)))


def segment_table(track: Track, config: SynthConfig) -> list[list[Segment | None]]:
    """table[a][b - a - 1]: the segment written on samples a .. b, for every a < b up to the first b past which
    no pace can be written (kinds.pace_possible); the row ends there."""
    samples, out = track.samples, []
    for a in range(track.n - 1):
        m, row = Summary.start(samples[a]), []
        for b in range(a + 1, track.n):
            m = m.then(samples[b], samples[b - 1], track.steps, b - 1, config)
            row.append(written_segment(m, config))
            if not pace_possible(m, config):
                break  # no longer interval from a has a pace either: the row ends here
        out.append(row)
    return out


@dataclass(frozen=True)
class Segmented:
    """A track's minimum-cost behaviour and the boundary samples synthesis chose (b_0 = 0 .. b_m = n - 1)."""

    behaviour: Behaviour
    boundaries: tuple[int, ...]


def segment_track(track: Track, config: SynthConfig, after=None) -> Segmented:
    """The minimum-cost behaviour of a track among those synthesis writes (parked when it holds)."""
    samples = track.samples
    if all(s.speed <= config.v_stop for s in samples):
        return Segmented(Behaviour(track.id, (), after), (0, track.n - 1))
    if track.n == 1:
        only = written_segment(Summary.start(samples[0]), config)
        if only is None:  # a lone moving sample with no path writable cannot happen: heading holds on one sample
            raise AssertionError(f"no segment for the one sample of {track.id}")
        return Segmented(Behaviour(track.id, (only,), after), (0, 0))
    table = segment_table(track, config)
    n = track.n
    best: list[tuple[int, int] | None] = [None] * n  # (cost from a to the end, the chosen b)
    best[n - 1] = (0, n - 1)
    for a in range(n - 2, -1, -1):
        choice = None
        row = table[a]
        for b in range(a + len(row), a, -1):  # the longest first: ties keep the largest b
            seg, rest = row[b - a - 1], best[b]
            if seg is None or rest is None:
                continue
            cost = seg.cost + rest[0]
            if choice is None or cost < choice[0]:
                choice = (cost, b)
        best[a] = choice
    if best[0] is None:
        raise AssertionError(f"no behaviour for {track.id}: a one-step segment is always writable")
    bounds, segments, a = [0], [], 0
    while a < n - 1:
        b = best[a][1]
        segments.append(table[a][b - a - 1])
        bounds.append(b)
        a = b
    return Segmented(Behaviour(track.id, tuple(segments), after), tuple(bounds))

