"""Heavy loads (issue #24 item 7): when no set of contacts can push the object along the
segment, the contact-force LP knows it before anyone pushes, and the transport fails
``too_heavy`` at once instead of re-arranging nine times and then failing ``stalled``; where a
larger set can push it, the re-arrangement takes more pushers (up to every robot).

The cases are set by the share of the fleet's summed force (six robots of 6 N, 36 N) the floor
friction needs, not tuned to one object: a crate pushed on its 0.5 m face (two robots fit
there) and a long crate pushed on its 1.2 m face."""

from __future__ import annotations

import numpy as np
import pytest

from controller.events import by_kind
from controller.planning.arrangement import plan_arrangement
from tests.support.transport_mission import lp_feasible, mission, view
from tests.support.transport_scenarios import CRATE, Scenario, scenario_config

LONG_CRATE = [[0.0, 0.0], [0.6, 0.0], [0.6, 1.2], [0.0, 1.2]]
FLEET_N = 36.0  # six robots of 6 N
MU = 0.3


def heavy(polygon, share: float, goal=(4.5, 2.5, 0.0)) -> Scenario:
    """An object whose floor friction needs ``share`` of the fleet's summed force."""
    mass = share * FLEET_N / (MU * 9.81)
    return Scenario("heavy", polygon, (1.5, 2.5, 0.0), goal, mass=mass, floor_friction=MU)


def arrangement(sc: Scenario, twist):
    m, cfg, _ = mission(sc)
    a = plan_arrangement(
        cfg, m.model, np.asarray(twist, float), m.params.speed, 6.0, len(cfg.robots),
        m.s.turn_margin, np.random.default_rng(0),
    )  # fmt: skip
    return m, a


@pytest.mark.parametrize(
    "polygon, share, twist",
    [
        (CRATE, 0.4, (1.0, 0.0, 0.0)),  # 14.4 N on a face two robots of 6 N fit on
        (CRATE, 0.5, (1.0, 0.0, 0.0)),
        (LONG_CRATE, 0.4, (0.0, 1.0, 0.0)),  # along its length: its 0.6 m face
        (LONG_CRATE, 0.7, (1.0, 0.0, 0.0)),  # 25 N: more than its back face's robots
    ],
    ids=["crate-40%-x", "crate-50%-x", "long-40%-y", "long-70%-x"],
)
def test_a_push_no_set_of_contacts_can_make_is_refused_with_its_reason(polygon, share, twist):
    m, a = arrangement(heavy(polygon, share), twist)
    need = share * FLEET_N
    assert not a.feasible
    assert f"needs {need:.1f} N" in a.detail and f"{FLEET_N:.1f} N in all" in a.detail
    assert not lp_feasible(m, a.points, a.normals, np.asarray(twist) * m.params.speed, 6.0)


@pytest.mark.parametrize(
    "polygon, share, twist",
    [
        (CRATE, 0.4, (0.0, 1.0, 0.0)),  # the same crate, pushed on its 0.8 m face
        (LONG_CRATE, 0.5, (1.0, 0.0, 0.0)),  # 18 N on the 1.2 m face: four pushers
        (LONG_CRATE, 0.4, (0.7071, 0.7071, 0.0)),  # diagonal: the set takes every robot
    ],
    ids=["crate-40%-y", "long-50%-x", "long-40%-diagonal"],
)
def test_a_push_a_larger_set_can_make_gets_that_set(polygon, share, twist):
    m, a = arrangement(heavy(polygon, share), twist)
    assert a.feasible and a.pushers >= 4
    assert lp_feasible(m, a.points, a.normals, np.asarray(twist) * m.params.speed, 6.0)


def test_a_crate_too_heavy_at_every_heading_fails_too_heavy_before_anyone_pushes():
    """Floor friction 82 % of the fleet's summed force (29.4 N of 36 N): the fleet's force
    would do, but at no heading do enough robots fit on the faces that push it (the LP over
    every candidate contact proves it: no set reaches 100 %). The transport fails
    ``too_heavy`` on its first tick, nobody asked to push or move, the proof in the detail."""
    m, cfg, poses = mission(heavy(CRATE, 29.43 / FLEET_N))
    out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
    assert (
        out.report.outcome.failed
        and out.report.outcome.reason == "too_heavy"
        and np.all(out.command.velocities == 0.0)
    )
    detail = by_kind(out.report.events)["failure"].detail
    assert "at any heading" in detail and "needs 29.4 N" in detail
    assert "no set reaches more than" in detail  # the bound: a proof, not a search given up
    assert m.pusher.plans == 0 and m.grip.relocations == 0 and m.rearranger.count == 0


def test_a_crate_the_robots_cannot_push_along_the_route_gets_a_route_they_can():
    """Floor friction 40 % of the fleet's summed force (14.4 N of 36 N), the goal along x, the
    crate's 0.5 m face toward it (two robots fit there, 12 N): the route pushes the crate on
    its 0.8 m face, diagonally on two faces or turned. Every straight move of the route is one
    the fleet can push at the heading it is made at; the route of before (straight along x)
    was not. (Before, the transport
    failed ``too_heavy`` at once; the pybullet scenario ``turned-crate-pybullet`` delivers.)"""
    from controller.mission.progress import route_planner_for
    from controller.planning.route import RoutePlanner

    cfg = scenario_config(heavy(CRATE, 0.4))
    start = np.asarray(cfg.object.start, float)
    plain = RoutePlanner.from_config(cfg).plan(start)
    planner = route_planner_for(cfg)
    turned = planner.plan(start)
    assert plain.ok and turned.ok
    push = planner.push
    assert _moves(plain) and not all(push.can_push(a) for _, a in _moves(plain))
    moves = _moves(turned)
    assert moves and all(push.can_push(a) for _, a in moves)
    # none of the way is pushed on the 0.5 m face alone (object-frame direction ±x)
    assert all(abs(np.sin(a)) > 0.5 for _, a in moves)


def _moves(route) -> list[tuple[float, float]]:
    """(length m, object-frame direction rad) of a route's straight moves between subgoals."""
    wp = route.waypoints
    out = []
    for a, b in zip(wp[:-1], wp[1:], strict=True):
        if abs(b[2] - a[2]) < 1e-12 and np.hypot(*(b[:2] - a[:2])) > 1e-9:
            d = b[:2] - a[:2]
            out.append((float(np.hypot(*d)), float(np.arctan2(d[1], d[0]) - a[2])))
    return out
