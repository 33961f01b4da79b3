"""The speed profile of a simulated variant's segment (synth.behaviour.variants, docs/scenic.md "Simulated
variants"): for random segment plans that keep each segment's recorded length, every draw's piecewise-linear
profile (boundary speed, knot at half-time, boundary speed) covers the segment's length and obeys its pace, checked
against an independent brute force (a fine Riemann sum of speeds, each sampled speed tested against the pace)."""

from __future__ import annotations

from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString

from synth.behaviour.kinds import Cruising, FollowingLane, SlowingDown, SlowingToAStop, SpeedingUp, Stopped
from synth.behaviour.program import Behaviour, Segment
from synth.behaviour.track import Sample, Steps, Track
from synth.behaviour.variants import along, arc_lengths, feasible, knot, pose_at, profile, speed_plan
from synth.config import as_config
from synth.syntax import Range

CONFIG = as_config(None)
PACES = ("cruising", "speeding up", "slowing down", "slowing to a stop", "stopped")


@st.composite
def plans(draw):
    """A behaviour of 1 to 4 segments of random paces over a track whose recorded speeds are a random profile of
    that shape, each segment's recorded mean speed, and a draw."""
    dv, v_stop = CONFIG.dv, CONFIG.v_stop
    m = draw(st.integers(1, 4))
    kinds = [draw(st.sampled_from(PACES)) for _ in range(m)]
    speeds, segs, means, durations = [draw(st.floats(v_stop + 0.1, 15))], [], [], []
    for kind in kinds:
        u = speeds[-1]
        if kind == "cruising":
            w = draw(st.floats(max(0.0, u - 2), u + 2))
        elif kind == "speeding up":
            w = u + draw(st.floats(dv, 5))
        elif kind == "slowing down":
            w = max(0.0, u - draw(st.floats(dv, 5)))
        else:
            w = draw(st.floats(0, v_stop))
        assume(kind != "slowing down" or u - w >= dv)
        assume(kind != "slowing to a stop" or u > v_stop)
        assume(kind != "stopped" or u <= v_stop)
        # the recorded mean: between the boundary speeds (a monotone recording's), a share of the way
        if kind == "cruising":
            mean = (u + w) / 2 + draw(st.floats(-0.2, 0.2))
        else:
            mean = u + (w - u) * draw(st.floats(0.3, 0.7))
        low = max(0.0, min(u, w, mean) - draw(st.floats(0, 1)))
        high = max(u, w, mean) + draw(st.floats(0, 1))
        ranged = {"cruising": Cruising, "speeding up": SpeedingUp, "slowing down": SlowingDown}
        pace = ranged[kind](Range(low, high)) if kind in ranged else \
            (SlowingToAStop() if kind == "slowing to a stop" else Stopped())
        segs.append(Segment(None if kind == "stopped" else FollowingLane(), pace, Range(1.0, 1.0)))
        means.append(max(0.0, mean))
        durations.append(draw(st.floats(0.5, 5)))
        speeds.append(w)
    samples = tuple(Sample(float(k), v, 0.0) for k, v in enumerate(speeds))
    track = Track("car1", "Car", samples, Steps.of(samples, None), True)
    plan = speed_plan(Behaviour("car1", tuple(segs)), list(range(m + 1)), track, CONFIG, means)
    q = [draw(st.floats(a, b)) for a, b in zip(plan.lo, plan.hi)]
    return segs, plan, means, durations, q, draw(st.floats(0, 1))


def obeys(pace, speeds, eps=1e-6) -> bool:
    """Brute force: the pace's rules on a segment's sampled speeds (as synth.behaviour.kinds checks samples)."""
    dv, v_stop = CONFIG.dv, CONFIG.v_stop
    if isinstance(pace, Stopped):
        return max(speeds) <= v_stop + eps
    rising = all(b >= a - eps for a, b in zip(speeds, speeds[1:]))
    falling = all(b <= a + eps for a, b in zip(speeds, speeds[1:]))
    if isinstance(pace, SlowingToAStop):
        return speeds[0] > v_stop - eps and speeds[-1] <= v_stop + eps and falling
    inside = all(pace.range.lo - eps <= v <= pace.range.hi + eps for v in speeds)
    if isinstance(pace, SpeedingUp):
        return inside and rising and speeds[-1] - speeds[0] >= dv - eps
    if isinstance(pace, SlowingDown):
        return inside and falling and speeds[0] - speeds[-1] >= dv - eps
    return inside


@settings(max_examples=300, deadline=None)
@given(plans())
def test_every_drawn_profile_keeps_its_segments_length_and_pace(case):
    segs, plan, means, durations, q, f = case
    u = feasible(plan.recorded, plan.lo, plan.hi, plan.rows, q, f)
    assert plan.holds(u, 1e-6)
    kept = bool(plan.means)
    for j, (seg, mean, duration) in enumerate(zip(segs, means, durations)):
        middle = knot(u[j], u[j + 1], plan.means[j] if kept else None)
        n = 2000
        taus = [duration * k / n for k in range(n + 1)]
        speeds = [profile(u[j], middle, u[j + 1], duration, t)[0] for t in taus]
        assert obeys(seg.pace, speeds), (seg.pace, u[j], middle, u[j + 1])
        # the closed form's distance against a trapezoid sum of the sampled speeds
        area = sum((a + b) / 2 for a, b in zip(speeds, speeds[1:])) * duration / n
        assert abs(profile(u[j], middle, u[j + 1], duration, duration)[1] - area) <= 1e-6 * (1 + area)
        if kept:  # the segment's recorded length
            assert abs(area - mean * duration) <= 1e-6 * (1 + area)


def test_a_recording_whose_speeds_obey_the_plan_keeps_every_length():
    """The plan keeps the lengths where it can (a cruising segment whose mean lies in its Range)."""
    samples = tuple(Sample(float(k), v, 0.0) for k, v in enumerate([5.0, 5.5, 6.0]))
    track = Track("car1", "Car", samples, Steps.of(samples, None), True)
    segs = tuple(Segment(FollowingLane(), Cruising(Range(4.0, 7.0)), Range(1.0, 1.0)) for _ in range(2))
    assert speed_plan(Behaviour("car1", segs), [0, 1, 2], track, CONFIG, [5.2, 5.8]).means == (5.2, 5.8)
    # a mean its Range cannot reach with the recorded boundary speeds: the plan falls back to lengths that vary
    assert speed_plan(Behaviour("car1", segs), [0, 1, 2], track, CONFIG, [9.0, 5.8]).means == ()


@settings(max_examples=300, deadline=None)
@given(plans(), st.lists(st.floats(0, 50), min_size=4, max_size=4))
def test_the_place_along_the_path_covers_each_segments_recorded_length_at_its_pace(case, lengths):
    """`along`: whatever the draw, and whether or not the plan keeps the recorded mean speed, a segment covers its
    recorded length exactly by its end, never goes back, and its speed is the profile's (so its pace holds, as
    above); where the plan keeps the mean speed, the place is the speed's own integral (brute force: a trapezoid
    sum of the speeds)."""
    segs, plan, means, durations, q, f = case
    u = feasible(plan.recorded, plan.lo, plan.hi, plan.rows, q, f)
    kept = bool(plan.means)
    for j, (mean, duration) in enumerate(zip(means, durations)):
        length = mean * duration if kept else lengths[j]
        middle = knot(u[j], u[j + 1], plan.means[j] if kept else None)
        n = 400
        taus = [duration * k / n for k in range(n + 1)]
        places = [along(u[j], middle, u[j + 1], duration, t, length) for t in taus]
        assert places[0][1] == 0.0 and abs(places[-1][1] - length) <= 1e-9 * (1 + length)
        assert all(b[1] >= a[1] - 1e-12 for a, b in zip(places, places[1:]))
        assert [p[0] for p in places] == [profile(u[j], middle, u[j + 1], duration, t)[0] for t in taus]
        if kept:
            speeds = [p[0] for p in places]
            area = 0.0
            for k in range(1, n + 1, 40):
                area = sum((a + b) / 2 for a, b in zip(speeds[:k], speeds[1:k + 1])) * duration / n
                assert abs(places[k][1] - area) <= 1e-3 * (1 + length)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=8),
       st.lists(st.floats(-3, 3), min_size=8, max_size=8), st.data())
def test_the_pose_at_an_arc_length_lies_on_the_segments_recorded_places(points, turns, data):
    """`pose_at` against shapely: the point at arc length s of the segment's places (samples lo .. hi) is the
    polyline's point at that distance from its start, and its heading lies between its piece's two samples'."""
    points = [points[0], *(p for a, p in zip(points, points[1:]) if data.draw(st.booleans()) or p != a)]
    arcs = arc_lengths(points)
    headings = [sum(turns[:k]) for k in range(len(points))]
    lo = data.draw(st.integers(0, len(points) - 1))
    hi = data.draw(st.integers(lo, len(points) - 1))
    s = arcs[lo] + data.draw(st.floats(0, 1.2)) * (arcs[hi] - arcs[lo])
    x, y, h = pose_at(points, arcs, headings, lo, hi, s)
    if hi == lo or s >= arcs[hi]:
        assert (x, y, h) == (*points[hi], headings[hi])
        return
    expected = LineString(points[lo:hi + 1]).interpolate(s - arcs[lo])
    assert abs(x - expected.x) <= 1e-6 and abs(y - expected.y) <= 1e-6
    i = max(k for k in range(lo, hi) if arcs[k] <= s and arcs[k + 1] > s)
    assert min(headings[i], headings[i + 1]) - 1e-9 <= h <= max(headings[i], headings[i + 1]) + 1e-9
