"""Projective path planning (Table I, robot-robot rotation, the turn limit), envelope goals, and
the safety filter (osqp barrier certificates)."""

from __future__ import annotations

import numpy as np
import pytest

from controller import geometry
from controller.approach import (
    ApproachParams,
    capture_goals,
    plan_step,
    ray_exit,
    table_one,
    turn_toward,
)
from controller.safety import SafetyFilter, SafetyParams

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)


# -- Table I on hand-made geometry


def test_free_path_keeps_its_direction():
    rule, d = table_one(np.array([-0.5, 0.5]), 0.1, np.array([0.0, 1.0]), SQUARE, 0.02)
    assert rule == "free" and np.allclose(d, [0, 1])


def test_one_edge_hit_aligns_with_the_edge_along_the_heading():
    # projected disc touches the bottom edge only, heading up and a little right
    heading = np.array([0.3, 0.95])
    rule, d = table_one(
        np.array([0.5, -0.05]), 0.1, heading / np.linalg.norm(heading), SQUARE, 0.02
    )
    assert rule == "edge" and np.allclose(d, [1.0, 0.0])
    # heading up and a little left: the other way along the same edge
    rule, d = table_one(np.array([0.5, -0.05]), 0.1, np.array([-0.3, 0.95]) / 0.995, SQUARE, 0.02)
    assert rule == "edge" and np.allclose(d, [-1.0, 0.0])


def test_corner_hit_moves_along_the_bisector_away_from_the_object():
    rule, d = table_one(
        np.array([1.05, 1.05]), 0.1, np.array([-1.0, -1.0]) / np.sqrt(2), SQUARE, 0.02
    )
    assert rule == "corner" and np.allclose(d, [1 / np.sqrt(2), 1 / np.sqrt(2)])


def test_head_on_escapes_along_the_outward_normal():
    rule, d = table_one(np.array([0.5, 0.05]), 0.1, np.array([0.0, 1.0]), SQUARE, 0.02)
    assert rule == "head_on" and np.allclose(d, [0.0, -1.0])


def test_turn_limit_bounds_the_change_of_heading():
    h = turn_toward(np.array([0.0, 0.0]), np.array([np.pi / 2, -0.1]), np.radians(15))
    assert np.allclose(h, [np.radians(15), -0.1])


def test_robot_robot_rotation_finds_a_clear_direction():
    params = ApproachParams(max_turn=np.pi)
    pos = np.array([[0.0, 0.0], [0.4, 0.0]])
    goals = np.array([[2.0, 0.0], [0.4, 0.0]])
    active = np.array([True, False])
    res = plan_step(pos, np.array([0.1, 0.1]), goals, np.zeros((2, 2)), np.array([0.4, 0.4]),
                    np.zeros(2), [], active, params, np.random.default_rng(0))  # fmt: skip
    v = res.velocity[0]
    assert np.linalg.norm(v) > 0.1
    ang = np.degrees(abs(np.arctan2(v[1], v[0])))
    assert ang >= 15 - 1e-9  # rotated by at least alpha off the blocked straight line
    # the projected disc is clear of the other robot
    ahead = pos[0] + 0.25 * v / np.linalg.norm(v)
    assert np.linalg.norm(ahead - pos[1]) >= 0.2


def test_static_obstacle_is_skirted_not_entered():
    params = ApproachParams()
    wall = np.array([[0.5, -1.0], [0.7, -1.0], [0.7, 1.0], [0.5, 1.0]])
    pos = np.array([[0.0, 0.05]])
    heading = np.zeros(1)
    for _ in range(400):
        res = plan_step(pos, np.array([0.1]), np.array([[1.5, 0.0]]), np.zeros((1, 2)),
                        np.array([0.4]), heading, [wall], np.array([True]), params,
                        np.random.default_rng(1))  # fmt: skip
        heading = res.heading
        pos = pos + 0.05 * res.velocity
        assert geometry.polygon_signed_distance(pos, wall)[0] > 0.1 - 1e-6
    assert np.linalg.norm(pos[0] - [1.5, 0.0]) < 0.1


# -- goals on the envelope


def test_ray_exit_of_a_convex_polygon():
    t = ray_exit(np.array([[0.5, 0.5], [2.0, 0.5]]), np.array([[1.0, 0.0], [1.0, 0.0]]), SQUARE)
    assert np.allclose(t, [0.5, 0.0])


def test_notch_stations_are_outside_the_hull_or_pulled_apart():
    pts = np.array([[0.85, 0.4], [0.4, 0.85], [0.5, 0.0], [0.0, 0.5]])
    nrm = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]])
    params = ApproachParams()
    radii = np.full(4, 0.1)
    env, contact = capture_goals(pts, nrm, radii, np.array([2.0, 1.0, 0.3]), L_SHAPE, params)
    d = np.linalg.norm(env[:, None] - env[None], axis=-1) + np.eye(4) * 9
    assert d.min() >= 0.2 + params.station_gap - 1e-9
    world = geometry.transform(L_SHAPE, [2.0, 1.0, 0.3])
    # every station and contact goal leaves room for the disc
    assert np.all(geometry.polygon_signed_distance(env, world) >= 0.1 + params.contact_gap - 1e-9)
    assert np.allclose(geometry.polygon_signed_distance(contact, world), 0.1 + params.contact_gap)


# -- the safety filter


def make_filter(n, holonomic=True, obstacles=()):
    return SafetyFilter(
        np.full(n, 0.1), np.full(n, holonomic), np.full(n, 0.4),
        np.array([[0.0, 0.0], [10.0, 10.0]]), [np.asarray(o, float) for o in obstacles],
        SafetyParams(margin=0.05),
    )  # fmt: skip


@pytest.mark.parametrize("holonomic", [True, False])
def test_two_robots_driven_head_on_never_get_closer_than_the_margin(holonomic):
    sf = make_filter(2, holonomic)
    p = np.array([[4.0, 5.0], [6.0, 5.01]])
    gap = np.inf
    for _ in range(300):
        r = sf.filter(p, np.array([[0.35, 0.0], [-0.35, 0.0]]))
        assert r.status == "solved"
        p = p + 0.05 * r.velocities
        gap = min(gap, np.linalg.norm(p[0] - p[1]) - 0.2 - sf._grow.sum())
    assert gap >= 0.05 - 1e-3


def test_filter_keeps_robots_out_of_obstacles_and_inside_walls():
    box = [[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]]
    sf = make_filter(2, obstacles=[box])
    p = np.array([[3.0, 5.0], [0.5, 0.5]])
    for _ in range(300):
        r = sf.filter(p, np.array([[0.4, 0.0], [-0.3, -0.3]]))
        p = p + 0.05 * r.velocities
    assert geometry.polygon_signed_distance(p[:1], np.array(box))[0] >= 0.15 - 1e-3
    assert np.all(p[1] >= 0.15 - 1e-3)


def test_filter_leaves_a_safe_command_alone_and_stops_stale_robots():
    sf = make_filter(3)
    p = np.array([[1.0, 1.0], [5.0, 5.0], [8.0, 8.0]])
    v = np.array([[0.1, 0.2], [-0.2, 0.1], [0.2, 0.2]])
    r = sf.filter(p, v, stale=np.array([False, False, True]))
    assert np.allclose(r.velocities[:2], v[:2], atol=1e-4)
    assert np.allclose(r.velocities[2], 0.0)


def test_object_keeps_its_distance_except_for_a_robot_closing_in():
    sq = SQUARE + [4.0, 4.0]
    sf = make_filter(2)
    p = np.array([[3.5, 4.5], [5.5, 4.5]])
    exempt = np.array([True, False])
    for _ in range(200):
        r = sf.filter(p, np.array([[0.3, 0.0], [-0.3, 0.0]]), object_polygon=sq,
                      object_velocity=np.zeros(3), object_exempt=exempt)  # fmt: skip
        p = p + 0.05 * r.velocities
    d = geometry.polygon_signed_distance(p, sq)
    assert abs(d[0] - 0.1) < 1e-3  # allowed up to touching the object, never into it
    assert d[1] >= 0.15 - 1e-3  # kept off it
