"""Which ways the fleet can push the object (issue 34, item 9: ``planning.pushability``) and
the route that keeps to them: the LP bound over every candidate contact against a count by
hand, the bound above every set the transport would ask for, the heading slack, and the
restricted search the same in its fast and reference forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.mission.progress import route_planner_for
from controller.planning.pushability import PushDirections
from tests.support.transport_scenarios import CRATE, Scenario, scenario_config

MU = 0.3
FLEET_N = 36.0  # six robots of 6 N


def crate(share: float) -> PushDirections:
    """The 0.8 x 0.5 m crate whose floor friction needs ``share`` of the fleet's 36 N."""
    mass = share * FLEET_N / (MU * 9.81)
    sc = Scenario("heavy", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=mass, floor_friction=MU)
    return PushDirections.from_config(scenario_config(sc))


def test_the_bound_along_a_face_counts_the_robots_that_fit_on_it():
    """Along +x only the 0.5 m face pushes (frictionless contacts); robots of 0.1 m radius fit
    three on it (centres 0.2 m apart): 18 N. Along +y the 0.8 m face: four (24 N)."""
    p = crate(0.4)
    assert p.need == pytest.approx(14.4, abs=0.01)
    assert p.bound(0.0) * p.need == pytest.approx(3 * 6.0, rel=1e-6)
    assert p.bound(math.pi / 2) * p.need == pytest.approx(4 * 6.0, rel=1e-6)


def test_the_bound_is_above_every_set_the_transport_would_ask_for():
    p = crate(0.4)
    for a in np.radians(np.arange(0, 360, 15)):
        share, _ = p.capacity(a)
        assert share <= p.bound(a) + 1e-6, math.degrees(a)


def test_contact_friction_only_raises_the_bound():
    p = crate(0.4)
    sc = Scenario("heavy", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=p.model.mass,
                  floor_friction=MU, patch={"object": {"contact_friction": 0.3}})  # fmt: skip
    q = PushDirections.from_config(scenario_config(sc))
    assert q.model.contact_friction == 0.3
    for a in (0.0, 0.3, math.pi / 2):
        assert q.bound(a) >= p.bound(a) - 1e-9
    assert q.bound(0.3) > p.bound(0.3) + 0.01  # a slanted push gains from the cones


def test_a_direction_is_pushable_only_with_its_slack_around_it():
    """``can_push`` asks every bucket within the slack (10°) to overcome the floor friction:
    the edge of the pushable cone is not pushable, its middle is."""
    p = crate(0.4)
    ok = [p.capacity(math.radians(5 * b))[0] >= 1.0 for b in range(72)]
    for b in range(72):
        window = [ok[(b + k) % 72] for k in (-2, -1, 0, 1, 2)]
        assert p.can_push(math.radians(5 * b)) == all(window), 5 * b
    assert any(ok) and not all(ok)


def test_the_restricted_search_is_the_same_fast_and_reference():
    cfg = scenario_config(
        Scenario("heavy", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=4.89, floor_friction=MU)
    )
    planner = route_planner_for(cfg)
    start = np.asarray(cfg.object.start, float)
    planner.plan(start)  # the straight route cannot be pushed: restricted from now on
    assert planner._push_ok is not None
    a, b = planner.plan(start), planner.plan(start, reference=True)
    assert a.ok and b.ok
    np.testing.assert_allclose(a.waypoints, b.waypoints)
    assert (a.expanded, a.generated, a.cost) == (b.expanded, b.generated, b.cost)
