"""synth.pose.SE2, the one world pose transform: against homogeneous 3 x 3 matrices (an independent computation:
compose, inverse, round trips), and bit for bit against each formula it replaced (written out here as they were,
since golden outputs depend on their last bits)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.pose import BODY, EGO, SE2

coord = st.floats(-1e6, 1e6, allow_nan=False)
yaw = st.floats(-20.0, 20.0, allow_nan=False)  # radians, several turns either way
degrees = st.floats(-720.0, 720.0, allow_nan=False)
layout = st.sampled_from([BODY, EGO])
pose = st.builds(SE2, coord, coord, yaw, layout)
points = st.lists(st.tuples(coord, coord), min_size=1, max_size=8)


def matrix(p: SE2) -> np.ndarray:
    """The homogeneous matrix of a pose from its angle alone: the +x axis at yaw plus its quarter turns."""
    a = p.yaw + p.quarters * math.pi / 2
    return np.array([[math.cos(a), -math.sin(a), p.x], [math.sin(a), math.cos(a), p.y], [0.0, 0.0, 1.0]])


def close(a, b, scale: float) -> bool:
    return np.allclose(a, b, rtol=1e-9, atol=1e-9 * scale)


@settings(max_examples=200, deadline=None)
@given(pose, points)
def test_apply_and_local_are_the_matrix_and_its_inverse(p, pts):
    xs, ys = np.array(pts).T
    m = matrix(p)
    want = m @ np.vstack([xs, ys, np.ones(len(xs))])
    assert close(np.vstack(p.apply(xs, ys)), want[:2], 1e7)
    back = np.linalg.inv(m) @ np.vstack([xs, ys, np.ones(len(xs))])
    assert close(np.vstack(p.local(xs, ys)), back[:2], 1e7)
    assert close(np.vstack(p.local(*p.apply(xs, ys))), np.vstack([xs, ys]), 1e7)  # the round trip


@settings(max_examples=200, deadline=None)
@given(pose, pose, points)
def test_compose_is_the_matrix_product(a, b, pts):
    xs, ys = np.array(pts).T
    ab = a.compose(b)
    assert close(matrix(ab), matrix(a) @ matrix(b), 1e7)
    assert close(np.vstack(ab.apply(xs, ys)), np.vstack(a.apply(*b.apply(xs, ys))), 1e7)
    assert math.isclose(ab.heading_out(0.5), a.heading_out(b.heading_out(0.5)), abs_tol=1e-12)


@settings(max_examples=200, deadline=None)
@given(pose, points, yaw)
def test_inverse_undoes_the_pose(p, pts, h):
    xs, ys = np.array(pts).T
    inv = p.inverse()
    assert close(matrix(inv), np.linalg.inv(matrix(p)), 1e7)
    assert close(np.vstack(inv.apply(xs, ys)), np.vstack(p.local(xs, ys)), 1e7)
    assert close(matrix(p.compose(inv)), np.eye(3), 1e7)
    assert inv.heading_out(p.heading_out(h)) == h or math.isclose(inv.heading_out(p.heading_out(h)), h,
                                                                   abs_tol=1e-12)
    assert p.heading_in(p.heading_out(h)) == h or math.isclose(p.heading_in(p.heading_out(h)), h, abs_tol=1e-12)


@given(coord, coord, yaw)
def test_the_ego_layout_is_the_body_turned_a_quarter_clockwise(x, y, w):
    # ego +x is the body's -y (right), ego +y the body's +x (forward); headings from forward are the same
    body, ego = SE2.body(x, y, w), SE2.ego(x, y, w)
    assert (ego.c, ego.s) == (body.s, -body.c)
    assert close(ego.apply(1.0, 0.0), body.apply(0.0, -1.0), 1e7)
    assert close(ego.apply(0.0, 1.0), body.apply(1.0, 0.0), 1e7)
    assert ego.heading_in(w + 0.25) == body.heading_in(w + 0.25)


# The formulas SE2 replaced, as they were (extractors.base.global_to_ego, synth.world.WorldPose.point / local,
# synth.road.roadmap.in_ego_frame, extractors.argoverse2.CityPlaces, extractors.messages.ground_positions).

def old_global_to_ego(ego_x, ego_y, ego_yaw, xs, ys, yaws):
    dx = np.asarray(xs, dtype=float) - ego_x
    dy = np.asarray(ys, dtype=float) - ego_y
    c, s = math.cos(ego_yaw), math.sin(ego_yaw)
    return dx * s - dy * c, dx * c + dy * s, np.degrees(np.asarray(yaws, dtype=float) - ego_yaw) % 360.0


def old_world_point(wx, wy, heading, x, y):
    yaw = math.radians(heading)
    c, s = math.cos(yaw), math.sin(yaw)
    return wx + x * s + y * c, wy - x * c + y * s


def old_world_local(wx, wy, heading, x, y):
    yaw = math.radians(heading)
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = x - wx, y - wy
    return dx * s - dy * c, dx * c + dy * s


def old_in_ego_frame(x, y, heading, pts):
    yaw = math.radians(heading)
    c, s = math.cos(yaw), math.sin(yaw)
    a = np.asarray(pts, dtype=float) - (x, y)
    return a[:, 0] * s - a[:, 1] * c, a[:, 0] * c + a[:, 1] * s


def old_city_places(ex, ey, eyaw, tx, ty, box_yaw):
    c, s = np.cos(eyaw), np.sin(eyaw)
    return ex + c * tx - s * ty, ey + s * tx + c * ty, eyaw + box_yaw


def old_ground_position(px, py, yaw, bx, by):
    c, s = math.cos(yaw), math.sin(yaw)
    return px + c * bx - s * by, py + s * bx + c * by


def same_bits(a, b) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and a.tobytes() == b.tobytes()  # -0.0 and 0.0 differ, NaNs alike


edge_coord = st.one_of(coord, st.sampled_from([0.0, -0.0, 1e-300, -5e-324, 1e9]))
edge_yaw = st.one_of(yaw, st.sampled_from([0.0, -0.0, math.pi / 2, -math.pi, math.pi, 2 * math.pi]))
edge_degrees = st.one_of(degrees, st.sampled_from([0.0, -0.0, 90.0, 180.0, 270.0, 359.99999999999994]))


@settings(max_examples=300, deadline=None)
@given(edge_coord, edge_coord, edge_yaw, st.lists(st.tuples(edge_coord, edge_coord, edge_yaw), min_size=1,
                                                     max_size=8))
def test_world_to_ego_is_the_old_formula_bit_for_bit(ex, ey, ew, boxes):
    xs, ys, yaws = (np.array(v) for v in zip(*boxes))
    ego = SE2.ego(ex, ey, ew)
    x, y = ego.local(xs, ys)
    want = old_global_to_ego(ex, ey, ew, xs, ys, yaws)
    assert same_bits(x, want[0]) and same_bits(y, want[1])
    assert same_bits(np.degrees(ego.heading_in(yaws)) % 360.0, want[2])
    road = SE2.ego(ex, ey, math.radians(math.degrees(ew)))  # in_ego_frame's pose comes in degrees
    assert same_bits(np.vstack(road.local(xs, ys)), np.vstack(old_in_ego_frame(ex, ey, math.degrees(ew),
                                                                                np.c_[xs, ys])))


@settings(max_examples=300, deadline=None)
@given(edge_coord, edge_coord, edge_degrees, edge_coord, edge_coord)
def test_ego_to_world_and_back_are_the_old_formulas_bit_for_bit(wx, wy, heading, x, y):
    frame = SE2.ego(wx, wy, math.radians(heading))
    assert same_bits(frame.apply(x, y), old_world_point(wx, wy, heading, x, y))
    assert same_bits(frame.local(x, y), old_world_local(wx, wy, heading, x, y))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(edge_coord, edge_coord, st.one_of(edge_yaw, st.just(math.nan)), edge_coord, edge_coord,
                          edge_yaw), min_size=1, max_size=8))
def test_vehicle_to_world_is_the_old_formula_bit_for_bit(rows):
    ex, ey, eyaw, tx, ty, box = (np.array(v) for v in zip(*rows))
    ego = SE2.body(ex, ey, eyaw)  # one pose per row, numpy's cos and sin (Argoverse 2)
    want = old_city_places(ex, ey, eyaw, tx, ty, box)
    assert same_bits(np.vstack([*ego.apply(tx, ty), ego.heading_out(box)]), np.vstack(want))
    for r in rows:  # one pose, math's cos and sin (the log readers)
        if not math.isnan(r[2]):
            assert same_bits(SE2.body(*r[:3]).apply(r[3], r[4]), old_ground_position(*r[:5]))
