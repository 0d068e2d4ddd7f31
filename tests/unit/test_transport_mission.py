"""The transport mission's decisions, tick by tick on hand-made views (no bus, no world): the
route at the start, failing cleanly without one, delivery, progress measured along the route,
the contact sets of a re-arrangement, a robot lost on the way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import geometry
from controller.events import by_kind
from controller.mission.types import Phase
from controller.planning.arrangement import plan_arrangement
from controller.planning.hold import contact_wrenches
from tests.support.transport_mission import carry_job, lp_feasible, mission, view
from tests.support.transport_scenarios import CRATE, Scenario

OPEN = Scenario("open", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0))


def test_first_tick_plans_the_route_and_publishes_it():
    m, cfg, poses = mission(OPEN)
    out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
    kinds = [e.kind for e in out.report.events]
    assert "route" in kinds
    route = by_kind(out.report.events)["route"]
    wp = np.asarray(route.waypoints)
    assert np.allclose(wp[0], cfg.object.start, atol=1e-6)
    assert np.allclose(wp[-1], cfg.object.goal, atol=1e-6)
    assert route.length_m >= 3.0 - 1e-6
    assert m.phase in (Phase.TRANSPORT, Phase.REARRANGE)


def test_no_route_fails_cleanly_and_stops_every_robot():
    pen = (
        ((3.5, 1.5), (5.5, 1.5), (5.5, 1.7), (3.5, 1.7)),
        ((3.5, 3.3), (5.5, 3.3), (5.5, 3.5), (3.5, 3.5)),
        ((3.5, 1.5), (3.7, 1.5), (3.7, 3.5), (3.5, 3.5)),
        ((5.3, 1.5), (5.5, 1.5), (5.5, 3.5), (5.3, 3.5)),
    )
    m, cfg, poses = mission(Scenario("pen", CRATE, (1.5, 2.0, 0.0), (4.1, 2.2, 0.0), obstacles=pen))
    out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
    assert (
        out.report.outcome.failed and out.report.outcome.reason == "no_route" and out.command.stop
    )
    assert np.all(out.command.velocities == 0.0)
    assert by_kind(out.report.events)["failure"].detail


def test_delivered_inside_the_settle_margin_then_backs_off_and_is_done():
    m, cfg, poses = mission(OPEN)
    m.plan(view(cfg, 0.0, poses, cfg.object.start))
    goal = np.asarray(cfg.object.goal)
    shift = goal - np.asarray(cfg.object.start)
    at_goal = poses + shift  # the fleet carried it there
    near = goal + [0.05, 0.0, 0.0]  # 5 cm off: inside 0.6 x 0.2 m
    out = m.plan(view(cfg, 10.0, at_goal, near))
    assert m.phase == Phase.DONE and "delivered" in by_kind(out.report.events)
    assert not out.report.outcome.done  # backing off first
    c = geometry.transform(m.model.centroid[None], near)[0]
    for i in range(len(cfg.robots)):
        away = at_goal[i, :2] - c
        assert np.dot(out.command.velocities[i], away) > 0  # every robot moves away from the object
    out = m.plan(view(cfg, 20.0, at_goal, near))
    assert out.report.outcome.done


def test_progress_is_measured_along_the_route_not_as_the_crow_flies():
    pillar = (((2.8, 2.0), (3.2, 2.0), (3.2, 3.2), (2.8, 3.2)),)
    sc = Scenario("detour", CRATE, (1.0, 2.2, 0.0), (4.0, 2.2, 0.0), obstacles=pillar)
    m, cfg, poses = mission(sc)
    m.plan(view(cfg, 0.0, poses, cfg.object.start))
    wp = m.way.route.waypoints
    m.way.route_j = 0
    left = np.array([m.way.remaining(w, commit=True) for w in wp])
    assert np.all(np.diff(left) <= 1e-9)  # every step along the route is progress
    # from the start, the whole route is left (give or take a corner cut inside the window),
    # never the straight line through the pillar (3 m)
    assert left[-1] < 1e-6 and left[0] >= m.way.route.length_m - 0.05 > 3.5


def _arrangement(m, cfg, twist):
    """The re-arrangement set the mission would ask for (``planning.arrangement``)."""
    a = plan_arrangement(
        cfg,
        m.model,
        twist,
        m.params.speed,
        min(r.max_force for r in cfg.robots),
        len(cfg.robots),
        m.s.turn_margin,
        np.random.default_rng(0),
    )
    return a.points, a.normals, a.value, a.pushers, a.basis


def test_a_pushing_set_is_confirmed_by_the_lp_and_a_turning_set_turns():
    m, cfg, _ = mission(OPEN)
    fmax = min(r.max_force for r in cfg.robots)
    push = np.array([1.0, 0.0, 0.0])
    pts, nrm, value, n, basis = _arrangement(m, cfg, push)
    assert basis == "eq5" and n == len(pts) >= 2
    assert lp_feasible(m, pts, nrm, push * m.params.speed, fmax)
    assert np.all(nrm @ [-1.0, 0.0] > -1e-9)  # nobody pulls: the pushers face +x
    turn = np.array([0.0, 0.0, 1.0 / m.model.mean_radius])
    pts, nrm, value, n, basis = _arrangement(m, cfg, turn)
    assert basis == "lp_capacity" and value >= 1.0
    assert lp_feasible(m, pts, nrm, turn * m.params.speed, fmax)
    assert contact_wrenches(pts, nrm, m.model.centroid)[2].max() > 0  # a push turns it CCW


def test_a_heavy_object_recruits_free_robots():
    """Five robots' force is needed; two hold it at the start, the rest are free: the new set
    takes in free robots, and every robot of the set is confirmed by the LP."""
    long_crate = [[0.0, 0.0], [0.6, 0.0], [0.6, 1.2], [0.0, 1.2]]
    sc = Scenario(
        "heavy", long_crate, (1.5, 2.5, 0.0), (4.0, 2.5, 0.0), kinds="oooooooo", mass=10.0,
        floor_friction=0.3, max_force=8.0, patch={"capture": {"hold_force": 0.0}},
    )  # fmt: skip
    m, cfg, _ = mission(sc)
    push = np.array([1.0, 0.0, 0.0])
    pts, nrm, value, n, basis = _arrangement(m, cfg, push)
    held = sum(c is not None for c in m.grip.contacts.values())
    assert n >= 4 and len(pts) >= 4 and n > 0
    assert m.grip.n == len(cfg.robots) > held  # the free ones take part
    assert lp_feasible(m, pts, nrm, push * m.params.speed, 8.0)


def test_a_lost_robot_leaves_the_job_and_is_told_nothing():
    """The job's roster finds a holder gone during the carry: one ``robot_lost`` event, its
    contact dropped, the robot commanded nothing."""
    job, cfg, poses = carry_job(OPEN)
    job.plan(view(cfg, 0.0, poses, cfg.object.start))
    m = job.transport
    holder = next(i for i, c in m.grip.contacts.items() if c is not None)
    present = np.ones(len(cfg.robots), bool)
    present[holder] = False
    out = job.plan(view(cfg, 0.05, poses, cfg.object.start, present))
    lost = [e for e in out.report.events if e.kind == "robot_lost"]
    assert [(e.robot, e.phase) for e in lost] == [(cfg.robots[holder].id, str(job.phase))]
    assert lost[0].to_dict().keys() == {"t", "robot", "phase"}  # the carry's: no ``assigned``
    assert m.grip.contacts[holder] is None and holder not in m.grip.moves
    assert np.all(out.command.velocities[holder] == 0.0)
    out = job.plan(view(cfg, 0.1, poses, cfg.object.start, present))
    assert not [e for e in out.report.events if e.kind == "robot_lost"]  # reported once
    assert job.summary().plan is None and job.roster.lost == [holder]


def test_a_stall_with_a_robot_lost_fails_with_robot_lost():
    job, cfg, poses = carry_job(OPEN)
    job.plan(view(cfg, 0.0, poses, cfg.object.start))
    m = job.transport
    present = np.ones(len(cfg.robots), bool)
    present[0] = False
    job.plan(view(cfg, 0.05, poses, cfg.object.start, present))
    m.rearranger.futile = m.s.max_rearrangements  # nothing more to try
    t, out = 0.05, None
    while t < 3 * m.s.stall_timeout and not (out is not None and out.report.outcome.failed):
        t += 0.5
        out = job.plan(view(cfg, t, poses, cfg.object.start, present))  # the object never moves
    assert out is not None and out.report.outcome.failed
    failure = job.summary().transport.transport_failure
    assert out.report.outcome.reason == "robot_lost" and cfg.robots[0].id in failure["detail"]
    assert failure["reason"] == "robot_lost" and math.isclose(failure["t"], t)


def test_a_fleet_wide_silence_pauses_the_transport_and_loses_nobody():
    """Every robot gone for 1 s (one outage): every robot stopped, nobody dropped, the stall
    clock does not run; back, the transport goes on with the same contacts."""
    job, cfg, poses = carry_job(OPEN)
    job.plan(view(cfg, 0.0, poses, cfg.object.start))
    m = job.transport
    contacts = {i: c for i, c in m.grip.contacts.items()}
    stall0 = m.way.progress_t
    nobody = np.zeros(len(cfg.robots), bool)
    t = 0.05
    seen = []
    while t < 1.05:
        out = job.plan(view(cfg, t, poses, cfg.object.start, nobody))
        seen += [e.kind for e in out.report.events]
        assert out.command.stop and not out.report.outcome.failed
        t += 0.05
    assert seen == ["outage"] and not m.grip.lost
    assert m.way.progress_t - stall0 == pytest.approx(1.0, abs=0.06)  # paused, not stalled
    out = job.plan(view(cfg, t, poses, cfg.object.start))
    assert [e.kind for e in out.report.events][0] == "outage_end" and not m.grip.lost
    assert m.grip.contacts == contacts


def test_an_object_the_whole_fleet_cannot_push_fails_too_heavy_before_anyone_pushes():
    """Floor friction 0.6 × 20 kg × g ≈ 118 N against six robots of 6 N: no set of contacts
    moves it. The arrangement says so (the LP knows before anyone pushes) and the transport
    fails ``too_heavy`` at once, naming the force needed against the force available (before:
    nine re-arrangements, then ``stalled``). Only when the fleet's summed force falls short:
    a set short of its margin with force to spare is pushed as before (a turn), and where more
    robots fit, more are recruited (``test_a_heavy_object_recruits_free_robots``)."""
    for mass, friction, fleet_ok in ((20.0, 0.6, False), (12.0, 0.35, False)):
        sc = Scenario(
            "heavy", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=mass, floor_friction=friction
        )
        m, cfg, poses = mission(sc)
        out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
        assert (
            out.report.outcome.failed
            and out.report.outcome.reason == "too_heavy"
            and np.all(out.command.velocities == 0.0)
        )
        detail = by_kind(out.report.events)["failure"].detail
        need = friction * mass * 9.81
        assert f"needs {need:.1f} N" in detail and "36.0 N in all" in detail
        assert (need <= 36.0) is fleet_ok
        assert m.pusher.plans == 0 and m.grip.relocations == 0  # nobody asked to push or to move


def test_the_serpentine_counts_its_two_group_plans_and_switches():
    """``fleet run --json`` says how many of the serpentine's local plans had both of Sharma's
    groups manned and how often the pushing group switched (issue 34, item 1); a new segment
    or arrangement starts the groups afresh (a change there is no switch); the other
    strategies report None."""
    import dataclasses

    from controller.planning.transport import plan_local
    from controller.planning.transport_types import TransportParams
    from tests.support.transport_cases import diamond_case

    plan = plan_local(
        diamond_case(), TransportParams(strategy="serpentine"), np.random.default_rng(0)
    )
    assert plan.serpentine_groups == 2  # the diamond's two rear faces: one group each
    sc = Scenario("serp", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0),
                  patch={"transport": {"strategy": "serpentine"}})  # fmt: skip
    m, _, _ = mission(sc)
    p = m.pusher
    for group, groups in ((0, 2), (0, 2), (1, 2), (1, 1), (0, 2)):
        p._count_serpentine(dataclasses.replace(plan, serpentine_group=group,
                                                serpentine_groups=groups))  # fmt: skip
    p.forget()
    p._count_serpentine(dataclasses.replace(plan, serpentine_group=1, serpentine_groups=2))
    s = m.summary().to_json()
    assert (s["serpentine_plans"], s["serpentine_two_group_plans"]) == (6, 5)
    assert s["serpentine_switches"] == 2  # 0 → 1 and 1 → 0; not the one after forget()
    m_sa, _, _ = mission(Scenario("sa", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0)))
    assert m_sa.summary().to_json()["serpentine_plans"] is None


def test_a_short_turning_set_gets_the_benefit_of_the_doubt_once():
    """A set the LP finds short of its segment's wrench (capacity x margin < 1) is pushed the
    first time; come again after a re-arrangement that brought no progress, it is doubted (the
    transport plans a push-limited route again). Eq. 5's sets and sets that reach the wrench
    are never doubted; progress resets the count."""
    from controller.planning.arrangement import Arrangement

    m, _, _ = mission(Scenario("crate", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0)))
    pts, nrm = np.zeros((2, 2)), np.zeros((2, 2))
    short = Arrangement(pts, nrm, 0.7, 2, "lp_capacity")
    enough = Arrangement(pts, nrm, 1.0, 2, "lp_capacity")
    eq5 = Arrangement(pts, nrm, 0.7, 2, "eq5")
    r = m.rearranger
    r.futile = 1  # the first re-arrangement since the object last moved
    assert not r.doubted(short)
    r.futile = 2  # the one before brought no progress
    assert r.doubted(short)
    assert not r.doubted(enough) and not r.doubted(eq5)
    r.progressed()
    assert not r.doubted(short)
