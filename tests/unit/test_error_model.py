"""Planning with Yamashita et al.'s error model (Table 1, condition 2; issue 34 item 5):
``transport.errors`` gives the robots' motion error, the object's mass, floor friction and
centre of mass known to within a margin. Under it the plans count no push a robot is sent to
within the motion error of a vertex, keep robots twice the motion error apart, plan forces for
the heaviest, roughest object and make the torque for every centre of mass allowed. All 0 (the
default): condition 1, plans as before."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from controller import geometry
from controller.config import ConfigError
from controller.planning.arrangement import can_push, candidates, plan_arrangement, planning_model
from controller.planning.contact_lp import GRAVITY, ContactForceLP, required_wrench
from controller.planning.transport_model import ObjectModel, Rollout, robust_wrenches
from controller.planning.transport_types import (
    FOLLOW,
    PUSH,
    SLIDE_LEFT,
    SLIDE_RIGHT,
    TransportParams,
    TransportState,
)
from tests.support.config import make_config
from tests.support.transport_cases import BOX, node_near, robots_at, straight_route

YAMASHITA = {"position": [0.04, 0.01], "mass": 0.1, "friction": 0.1, "com": 0.01}
ERROR = math.hypot(0.04, 0.01)  # m: the motion error's norm, the margin the plans keep
POSE = np.array([3.0, 3.0, 0.0])


def test_the_error_model_is_off_by_default_and_reads_the_papers_values():
    plain = make_config({})
    p = TransportParams.from_config(plain.transport)
    assert (p.pose_error, p.com_error) == (0.0, 0.0)
    cfg = make_config({"transport": {"errors": YAMASHITA}})
    p = TransportParams.from_config(cfg.transport)
    assert p.pose_error == pytest.approx(ERROR) and p.com_error == 0.01
    # the object the plans see: the heaviest and roughest the margins allow
    nominal, worst = planning_model(plain), planning_model(cfg)
    assert worst.mass == pytest.approx(1.1 * plain.object.mass)
    assert worst.floor_friction == pytest.approx(1.1 * plain.object.floor_friction)
    assert nominal.mass == plain.object.mass and nominal.pushable.all()
    with pytest.raises(ConfigError, match="transport.errors.mass"):
        make_config({"transport": {"errors": {"mass": 1.5}}})


def test_candidate_contacts_keep_the_motion_error_from_every_vertex():
    cfg = make_config({"capture": {"spacing": 0.05}})
    poly = geometry.ensure_ccw(cfg.object_polygon())
    plain = candidates(cfg)
    near = geometry.vertex_distance(plain.points, poly) < ERROR
    assert near.any()  # at 0.05 m spacing the first node is 0.025 m from its vertex
    patch = {"capture": {"spacing": 0.05}, "transport": {"errors": YAMASHITA}}
    kept = candidates(make_config(patch))
    assert np.allclose(kept.points, plain.points[~near])


def _box_state(model: ObjectModel, ys: list[float], max_force: float = 10.0) -> TransportState:
    """Robots on the box's back edge (x = −0.3) at these heights, to push it along +x."""
    nodes = [node_near(model, (-0.3, y)) for y in ys]
    robots = robots_at(model, POSE, nodes, max_force=max_force)
    return TransportState(model, POSE, robots, _route())


def _route():
    from controller.planning.transport_types import RouteSegment

    return RouteSegment(straight_route(POSE, (6.0, 3.0, 0.0)))


def _slide_toward(roll: Rollout, i: int, y_to: float) -> int:
    """The slide action that moves robot i's node toward height ``y_to`` on the back edge."""
    n = roll.start.nodes[i]
    m = roll.model
    down = m.nodes[m.next_ccw[n]][1] < m.nodes[n][1]
    lower = y_to < m.nodes[n][1]
    return SLIDE_RIGHT if down == lower else SLIDE_LEFT


def _sliding(margin: float, ys: list[float], slide: float) -> tuple[ObjectModel, Rollout]:
    """The box with robots on its back edge at heights ``ys``, planned with the motion error
    ``margin`` (0: none), a slide covering ``slide`` m in one interval."""
    model = ObjectModel.build(BOX, 4.0, 0.2, 0.0, 0.1, push_margin=margin)
    state = _box_state(model, ys)
    dt = Rollout(state, TransportParams()).dt
    return model, Rollout(state, TransportParams(pose_error=margin, slide_speed=slide / dt))


@pytest.mark.parametrize("margin", [0.0, ERROR])
def test_a_push_a_plan_sends_a_robot_to_near_a_vertex_counts_for_nothing(margin):
    # two pushers at heights 0.1 and −0.13: only both together balance the torque (the
    # centroid at 0); robot 1 slides 0.04 m down, to 0.03 m from the corner, then pushes
    model, roll = _sliding(margin, [0.1, -0.13], 0.04)
    row0 = [FOLLOW, _slide_toward(roll, 1, -0.2)]
    trace = roll.run(np.array([row0] + [[PUSH, PUSH]] * 2, np.int64))
    n1 = trace.sims[1].nodes[1]
    assert geometry.vertex_distance(model.nodes[n1][None], model.polygon)[0] < ERROR
    if margin:  # it may be on the corner or past it: robot 0 alone cannot push the box
        assert trace.terms[1].infeasible and trace.terms[1].forces[1] == 0.0
    else:
        assert not trace.terms[1].infeasible and trace.terms[1].forces[1] > 0.0


def test_a_contact_held_near_a_vertex_at_the_plans_start_still_counts():
    # the held contact is measured: its error is in it already, the margin is not for it
    model = ObjectModel.build(BOX, 4.0, 0.2, 0.0, 0.1, push_margin=ERROR)
    state = _box_state(model, [0.1, -0.17])
    assert not model.pushable[node_near(model, (-0.3, -0.17))]
    roll = Rollout(state, TransportParams(pose_error=ERROR))
    trace = roll.run(np.array([[PUSH, PUSH]] * 2, np.int64))
    assert not trace.terms[0].infeasible and trace.terms[0].forces[1] > 0.0


@pytest.mark.parametrize("margin", [0.0, ERROR])
def test_robots_a_plan_brings_within_twice_the_motion_error_collide(margin):
    # centres 0.3 m apart (radii 0.1 each): robot 1 slides 0.08 m up, to 0.22 m from robot 0:
    # clear of it by 0.02 m, under the 2 × 0.041 m the error model keeps
    _, roll = _sliding(margin, [0.15, -0.15], 0.08)
    trace = roll.run(np.array([[FOLLOW, _slide_toward(roll, 1, 0.2)]], np.int64))
    gap = np.linalg.norm(trace.sims[1].pos[0] - trace.sims[1].pos[1])
    assert 0.2 < gap < 0.2 + 2 * ERROR
    assert trace.terms[0].collision == bool(margin)


def test_a_pair_already_that_near_at_the_plans_start_may_stay_so():
    model = ObjectModel.build(BOX, 4.0, 0.2, 0.0, 0.1, push_margin=ERROR)
    state = _box_state(model, [0.11, -0.11])  # centres 0.22 m apart from the start
    roll = Rollout(state, TransportParams(pose_error=ERROR))
    trace = roll.run(np.array([[PUSH, PUSH]] * 3, np.int64))
    assert not any(t.collision for t in trace.terms)


def test_sets_make_the_torque_for_every_centre_of_mass_the_error_allows():
    model = ObjectModel.build(BOX, 4.0, 0.2, 0.0, 0.1)
    lp = ContactForceLP(4)
    twist = np.array([0.1, 0.0, 0.0])
    # two back pushers, one of them weak: they balance the torque about the centroid, but a
    # centre of mass 1 cm toward the weak one asks more of it than it has
    pts = np.array([[-0.3, 0.1], [-0.3, -0.1]])
    inward = np.array([[1.0, 0.0], [1.0, 0.0]])
    need = 0.2 * 4.0 * GRAVITY  # 7.85 N, 3.92 N each when the CoM is the centroid
    fmax = np.array([need, 4.0])
    assert can_push(lp, model, twist, pts, inward, fmax)
    assert not can_push(lp, model, twist, pts, inward, fmax, com_error=0.01)
    # a set good for both extremes is good for every offset between them (the LP's feasible
    # wrenches are convex): checked at offsets drawn in the ±1 cm box
    strong = np.array([need, need])
    assert can_push(lp, model, twist, pts, inward, strong, com_error=0.01)
    w = required_wrench(twist, model.mass, model.floor_friction, model.mean_radius)
    assert len(robust_wrenches(w, 0.01)) == 2 and len(robust_wrenches(w, 0.0)) == 1
    rng = np.random.default_rng(7)
    for c in rng.uniform(-0.01, 0.01, (20, 2)):
        shifted = w + [0.0, 0.0, c[0] * w[1] - c[1] * w[0]]
        res = lp.solve(pts - model.centroid, inward, strong, np.ones(2, bool), shifted, 0.0,
                       model.mean_radius)  # fmt: skip
        assert res.feasible


def test_the_arrangement_keeps_the_margins():
    cfg = make_config({"transport": {"errors": YAMASHITA}})
    model = planning_model(cfg)
    poly = geometry.ensure_ccw(cfg.object_polygon())
    r = cfg.max_robot_radius
    weakest = min(x.max_force for x in cfg.robots)
    spare = max(cfg.capture.clearance, cfg.approach.safety_margin)
    for twist in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.6, -0.8, 0.0]):
        arr = plan_arrangement(cfg, model, np.array(twist), 0.15, weakest, len(cfg.robots),
                               1.2, np.random.default_rng(3))  # fmt: skip
        assert arr.feasible
        assert (geometry.vertex_distance(arr.points, poly) >= ERROR - 1e-9).all()
        centres = arr.points + r * arr.normals
        d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
        d[np.diag_indices(len(d))] = np.inf
        assert d.min() >= 2 * r + spare + 2 * ERROR - 1e-9


def test_an_object_too_heavy_only_for_the_error_model_says_so():
    from controller.planning.pushability import PushDirections
    from tests.support.transport_scenarios import CRATE, Scenario, scenario_config

    # a crate whose floor friction needs 30 % of the six robots' 36 N: pushable as configured;
    # planned 50 % heavier and rougher (2.25 times the force) no heading can be pushed
    mass = 0.3 * 36.0 / (0.3 * 9.81)
    sc = Scenario("heavy", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=mass, floor_friction=0.3)

    def directions(scenario):  # 12 directions, not 72: the test's time
        return replace(PushDirections.from_config(scenario_config(scenario)), buckets=12)

    plain = directions(sc)
    assert plain.best()[0] >= 1.0
    patch = {"transport": {"errors": {"mass": 0.5, "friction": 0.5}}}
    worst = directions(replace(sc, patch=patch))
    assert worst.need == pytest.approx(2.25 * plain.need)
    assert worst.best()[0] < 1.0
    detail = worst.too_heavy_detail()
    assert "50 % heavier" in detail and "transport.errors" in detail
    assert "transport.errors" not in plain.too_heavy_detail()
