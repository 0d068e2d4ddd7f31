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
from tests.support.transport_scenarios import CRATE, Scenario

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


def test_a_crate_too_heavy_for_the_robots_that_fit_fails_too_heavy_before_anyone_pushes():
    """Floor friction 40 % of the fleet's summed force (14.4 N of 36 N), the crate pushed along
    x on its 0.5 m face where two robots fit: the transport fails ``too_heavy`` on its first
    tick, nobody asked to push or move. Before, the fleet's summed force sufficed for the rule,
    the set short of the friction was pushed, and it failed ``stalled`` after nine
    re-arrangements."""
    m, cfg, poses = mission(heavy(CRATE, 0.4))
    out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
    assert (
        out.report.outcome.failed
        and out.report.outcome.reason == "too_heavy"
        and np.all(out.command.velocities == 0.0)
    )
    detail = by_kind(out.report.events)["failure"].detail
    assert "needs 14.4 N" in detail and "36.0 N in all" in detail
    assert m.pusher.plans == 0 and m.grip.relocations == 0 and m.rearranger.count == 1
