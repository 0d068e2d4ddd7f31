"""Sharma §4.3 as published: the two groups, the passive group's zero force, its motion."""

from __future__ import annotations

import math

import numpy as np

from controller.planning.serpentine import PASSIVE_GAP, passive_velocity, split_groups
from controller.planning.transport import plan_local
from controller.planning.transport_types import FOLLOW, PUSH, TransportParams
from tests.support.transport_cases import diamond_case, push_case

D = np.array([1.0, 0.0])


def unit(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])


def test_groups_take_forward_pushers_on_each_side_only():
    push = np.array([unit(30), unit(-30), unit(0), unit(0), unit(84), unit(180), [np.nan] * 2])
    offset = np.array([[0, -0.2], [0, 0.2], [-0.3, 0.1], [-0.3, -0.1], [0, -0.3], [0.3, 0], [0, 0]])
    g = split_groups(push, offset, D)
    assert g[0] == 0 and g[1] == 1  # toward the left / the right of the route
    assert sorted(g[2:4].tolist()) == [0, 1]  # straight pushers split between the groups
    assert g[4] == -1  # 84° off the route: it grazes D, it joins no group (it did before)
    assert g[5] == -1 and g[6] == -1  # pulls backwards / no contact


def test_straight_pushers_even_out_the_groups():
    push = np.array([unit(20), unit(20), unit(0), unit(0), unit(0)])
    offset = np.array([[0, -0.2], [0, -0.1], [-0.3, 0.1], [-0.3, -0.1], [-0.3, 0.0]])
    g = split_groups(push, offset, D)
    assert abs(int(np.sum(g == 0)) - int(np.sum(g == 1))) <= 1


def test_passive_group_carries_zero_force_in_every_interval():
    p = TransportParams(strategy="serpentine", intervals=10)
    for st in (diamond_case(), push_case(n_robots=6, max_force=12.0)):
        plan = plan_local(st, p, np.random.default_rng(0))
        passive = plan.effective != PUSH
        assert np.all(plan.forces[passive] == 0.0)
        assert np.any(plan.effective == FOLLOW)
        # only one group pushes in an interval
        for row, group in zip(plan.effective, [plan.serpentine_group], strict=False):
            assert np.any(row == PUSH) or group is None


def test_passive_robot_moves_with_the_object_and_never_into_it():
    pose = np.array([2.0, 1.0, 0.3])
    vel = np.array([0.1, 0.02, 0.05])  # the object's measured motion
    inward = unit(10)
    centre = np.array([1.5, 1.1])
    target = centre - PASSIVE_GAP * inward
    v = passive_velocity(target, target, inward, pose, vel, gain=2.0, vmax=1.0, gap=0.0)
    rel = target - pose[:2]
    at_contact = vel[:2] + vel[2] * np.array([-rel[1], rel[0]])
    assert np.allclose(v, at_contact)  # on its spot: exactly the object's motion there
    v_touch = passive_velocity(centre, centre, inward, pose, vel, gain=2.0, vmax=1.0)
    rel = centre - pose[:2]
    at_c = vel[:2] + vel[2] * np.array([-rel[1], rel[0]])
    assert (v_touch - at_c) @ inward < 0  # touching: it backs off relative to the object
    assert (
        np.linalg.norm(passive_velocity(centre, centre - 5 * inward, inward, pose, vel, 2.0, 0.3))
        <= 0.3 + 1e-12
    )


def test_mission_gives_every_robot_an_eq5_point_under_serpentine():
    """§4.1: the pushing set is Eq. 5's for as many pushers as robots (no capture contact is
    kept beside it), and every robot is assigned one of its points."""
    from controller.mission.guard import SafetyStage
    from controller.mission.transport import TransportMission
    from controller.planning.arrangement import plan_arrangement
    from tests.support.transport_scenarios import CRATE, Scenario, scenario_config

    sc = Scenario("open", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0))
    sc = Scenario(**{**sc.__dict__, "patch": {"transport": {"strategy": "serpentine"}}})
    cfg = scenario_config(sc)
    m = TransportMission(cfg, np.random.default_rng(0), SafetyStage(cfg), [], [], [])
    push = np.array([1.0, 0.0, 0.0])
    a = plan_arrangement(
        cfg, m.model, push, m.params.speed, min(r.max_force for r in cfg.robots),
        len(cfg.robots), m.s.turn_margin, np.random.default_rng(0), m.params.strategy,
    )  # fmt: skip
    pts, nrm, n, basis = a.points, a.normals, a.pushers, a.basis
    assert basis == "eq5" and n == len(pts) == len(cfg.robots)
    forward = -nrm @ D
    assert np.all(forward > -1e-9)  # nobody pulls (side points add nothing: they stay passive)
    assert np.sum(forward > 0.26) >= 2  # forward pushers for the two groups
