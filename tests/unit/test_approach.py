"""Projective planner (Sharma et al. §3): Table I rules, turn limit, robot rotation, envelope."""

from __future__ import annotations

import numpy as np
import pytest

from controller import geometry
from controller.planning import approach
from controller.planning.approach import CORNER, EDGE, HEAD_ON, NO_HIT, classify

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def unit(a):
    return np.array([np.cos(a), np.sin(a)])


def test_no_hit_keeps_heading():
    case, d = classify(np.array([-1.0, 0.5]), unit(np.pi), 0.1, 2.5, SQUARE)
    assert case == NO_HIT
    assert np.allclose(d, unit(np.pi))


def test_one_edge_aligns_with_edge_along_heading():
    # below the bottom edge, heading up and a little right: slide right along the edge
    case, d = classify(np.array([0.5, -0.3]), unit(np.deg2rad(80)), 0.1, 2.5, SQUARE)
    assert case == EDGE
    assert np.allclose(d, [1.0, 0.0])
    # heading up and a little left: slide left
    case, d = classify(np.array([0.5, -0.3]), unit(np.deg2rad(100)), 0.1, 2.5, SQUARE)
    assert case == EDGE
    assert np.allclose(d, [-1.0, 0.0])


def test_corner_goes_along_bisector_away():
    # toward the bottom-right corner from outside, diagonally
    c = np.array([1.15, -0.15])
    case, d = classify(c, unit(np.deg2rad(135)), 0.1, 2.5, SQUARE)
    assert case == CORNER
    assert np.allclose(d, unit(-np.pi / 4))
    assert np.dot(d, c - np.array([1.0, 0.0])) > 0  # away from the object


def test_head_on_escapes_along_outward_normal():
    case, d = classify(np.array([0.5, 0.05]), unit(np.pi / 2), 0.1, 2.5, SQUARE)
    assert case == HEAD_ON
    assert np.allclose(d, [0.0, -1.0])
    case, d = classify(np.array([0.9, 0.5]), unit(np.pi), 0.1, 2.5, SQUARE)
    assert case == HEAD_ON
    assert np.allclose(d, [1.0, 0.0])


def test_turn_limit():
    cur = np.array([[1.0, 0.0]])
    out = approach.turn_limited(cur, np.array([[0.0, 1.0]]), np.deg2rad(15))
    assert np.allclose(out, [unit(np.deg2rad(15))])
    out = approach.turn_limited(cur, np.array([unit(np.deg2rad(10))]), np.deg2rad(15))
    assert np.allclose(out, [unit(np.deg2rad(10))])


def test_robot_rotation_widens_alpha_until_clear():
    centers = np.array([[0.0, 0.0], [0.25, 0.0]])
    radii = np.array([0.1, 0.1])
    rng = np.random.default_rng(0)
    d = approach.robot_rotation(
        0, centers, radii, np.array([1.0, 0.0]), 2.5, np.deg2rad(15), 1.25, np.pi, rng
    )
    assert d is not None
    ang = abs(np.arctan2(d[1], d[0]))
    assert ang > np.deg2rad(15)  # 15 deg was not enough: widened by 1.25 steps
    ahead = centers[0] + 0.25 * d
    assert np.linalg.norm(ahead - centers[1]) >= 0.2
    # with a tight bound the robot stops this tick
    none = approach.robot_rotation(
        0, centers, radii, np.array([1.0, 0.0]), 2.5, np.deg2rad(15), 1.25, np.deg2rad(20), rng
    )
    assert none is None


def test_robot_rotation_sign_from_generator():
    centers = np.array([[0.0, 0.0], [0.25, 0.0]])
    radii = np.array([0.1, 0.1])
    signs = set()
    for seed in range(10):
        d = approach.robot_rotation(
            0, centers, radii, np.array([1.0, 0.0]), 2.5, np.deg2rad(15), 1.25, np.pi,
            np.random.default_rng(seed),
        )  # fmt: skip
        signs.add(np.sign(d[1]))
    assert signs == {-1.0, 1.0}


def test_envelope_contains_grown_polygon_and_images_on_it():
    env = approach.envelope(SQUARE, 0.25)
    ang = np.linspace(0, 2 * np.pi, 64)
    pts = (SQUARE[:, None] + 0.249 * np.stack([np.cos(ang), np.sin(ang)], 1)[None]).reshape(-1, 2)
    assert geometry.points_in_polygon(pts, env).all()
    img = approach.ray_to_convex(np.array([[0.5, 0.0]]), np.array([[0.0, -1.0]]), env)
    assert abs(img[0, 1] + 0.25) < 0.01 and abs(img[0, 0] - 0.5) < 1e-9


def test_plan_velocities_respects_limits_and_object():
    params = approach.PlannerParams(np.deg2rad(15), 2.5, np.deg2rad(15), 1.25, np.pi)
    centers = np.array([[0.5, -0.3], [3.0, 3.0]])
    heads = np.array([[0.0, 1.0], [1.0, 0.0]])
    goals = np.array([[0.5, 0.5], [5.0, 3.0]])
    vel, _, cases = approach.plan_velocities(
        centers, heads, np.array([0.1, 0.1]), np.array([0.4, 0.4]), goals, np.zeros((2, 2)),
        [SQUARE], np.ones((2, 1), bool), np.ones(2, bool), params, np.random.default_rng(0),
    )  # fmt: skip
    assert np.all(np.linalg.norm(vel, axis=1) <= 0.4 + 1e-9)
    assert cases[0] in (EDGE, CORNER)  # goal inside the object: deflected, not driven in
    assert vel[0, 1] <= 1e-9
    assert cases[1] == NO_HIT and vel[1, 0] > 0


def test_limit_accel():
    v = approach.limit_accel(np.array([[1.0, 0.0]]), np.zeros((1, 2)), np.array([1.0]), 0.05)
    assert np.allclose(v, [[0.05, 0.0]])


def test_build_mission_with_a_capture_set():
    from controller.mission.basic import GotoMission
    from controller.mission.capture import CaptureMission
    from controller.mission.factory import build_mission
    from controller.mission.job import CaptureJob
    from tests.support.capture_sets import l_shape_points
    from tests.support.config import make_config

    cfg = make_config({"sim": {"backend": "ideal"}})
    pts, nrm = l_shape_points()
    m = build_mission(cfg, capture=(pts, nrm, np.array([0, 1, 2, 3])))
    assert isinstance(m, CaptureMission)
    assert isinstance(build_mission(cfg, "stage"), GotoMission)
    assert isinstance(build_mission(cfg), CaptureJob)  # the GA plan, assigned on first sight
    s = m.summary()
    assert s.phase == "approach" and s.arrival_spread_s is None


def test_interception_meets_an_oncoming_target_as_fast_as_the_robot_or_faster():
    """Analytic oracles: a target coming head-on at the robot's speed is met halfway (5 s for
    10 m at 1 m/s each); one twice as fast after 10/3 s; one passing 5 m off the robot's line
    at 2 m/s where |(10 - 2T, 5)| = T, T = 5 s. A target running away as fast is never met
    (the horizon); a slower one is caught (20 s at 1 m/s against 0.5 m/s from 10 m). Before,
    only a target slower than the robot was met: the oncoming ones got the horizon."""
    robot = np.array([[0.0, 0.0]])
    speed = np.array([1.0])

    def meet(target, velocity, **kw):
        t = approach.interception_times(robot, np.array([target]), np.array([velocity]), speed,
                                        100.0, **kw)  # fmt: skip
        return float(t[0, 0])

    assert meet([10.0, 0.0], [-1.0, 0.0]) == pytest.approx(5.0)
    assert meet([10.0, 0.0], [-2.0, 0.0]) == pytest.approx(10.0 / 3.0)
    assert meet([10.0, 5.0], [-2.0, 0.0]) == pytest.approx(5.0)
    assert meet([10.0, 0.0], [1.0, 0.0]) == 100.0
    assert meet([10.0, 0.0], [0.5, 0.0]) == pytest.approx(20.0)
    assert meet([10.0, 20.0], [-2.0, 0.0]) == 100.0  # passes too far off to be reached
    assert meet([10.0, 0.0], [-1.0, 0.0], oncoming=False) == 100.0  # the rule before


def test_a_robot_heading_for_a_far_meeting_point_goes_at_full_speed():
    """A robot 5 m from its meeting point with an object that comes at it at 0.45 m/s (the goal
    moves toward the robot): the meeting point is already predicted, so it goes there at full
    speed; riding on the goal's velocity (the rule before, ``ride_reach=None``) left it
    0.05 m/s. At the goal it rides on all of it."""
    base = dict(max_turn=np.pi, projection=2.5, alpha=np.deg2rad(15), alpha_growth=1.25,
                alpha_max=np.pi)  # fmt: skip

    def step(centre, ride_reach):
        params = approach.PlannerParams(**base, ride_reach=ride_reach)
        vel, _, _ = approach.plan_velocities(
            np.array([centre]), np.array([[-1.0, 0.0]]), np.array([0.1]), np.array([0.5]),
            np.array([[5.0, 0.0]]), np.array([[0.45, 0.0]]), [], np.zeros((1, 0), bool),
            np.ones(1, bool), params, np.random.default_rng(0),
        )  # fmt: skip
        return vel[0]

    assert step([10.0, 0.0], 1.0) == pytest.approx([-0.5, 0.0])
    assert step([10.0, 0.0], None) == pytest.approx([-0.05, 0.0])
    assert step([5.0, 0.0], 1.0) == pytest.approx([0.45, 0.0])
