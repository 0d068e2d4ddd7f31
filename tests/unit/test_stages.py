"""Each stage of the job on its own, as a table: what it is given in a tick → what it reports
(the cue or failure the sequence reads, what it counts, whom it drops). The sequence's own table
is tests/unit/test_sequence.py; these are the stages that feed it: the capture's phase logic
(``capture_phase.advance``), the roster, the outage watch, the route progress and the
re-arrangement's counters."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from controller.mission.capture_phase import CaptureSettings, CaptureState, Measures, advance
from controller.mission.job import CaptureJob
from controller.mission.outage import OutageWatch
from controller.mission.planners import DeferredPlanners
from controller.mission.progress import ProgressSettings, RouteProgress
from controller.mission.rearrange import Rearranger
from controller.mission.roster import LOST_STALE_S, Roster
from controller.mission.sequence import Cue
from controller.mission.types import FleetView, Phase, Reason
from controller.planning.transport_model import ObjectModel
from tests.support.config import make_config
from tests.support.transport_mission import carry_job
from tests.support.transport_mission import view as tview
from tests.support.transport_scenarios import CRATE, Scenario

P = Phase
S = CaptureSettings()
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
ON, OFF = 0.5 * S.envelope_tolerance, 2.0 * S.envelope_tolerance  # a robot's way to its target
TOUCH, APART = 0.5 * S.contact_tolerance, 1.5 * S.contact_tolerance  # a robot's gap
RELEASED = 1.1 * S.release_factor * S.contact_tolerance

# ------------------------------------------------------------------ the capture's phase logic
HOLD_AT, ARREST_AT = 10.0, 20.0


def row(why, phase, t, dist, gap, moved=0.0, detouring=False, cue=None, reason=None, kinds=()):
    """(the job's phase, t, each robot's way to its target, its gap, the object moved by (m),
    a detour still on) → (the cue, the failure's reason, the events' kinds)."""
    return pytest.param(phase, t, dist, gap, moved, detouring, (cue, reason, list(kinds)), id=why)


CAPTURE = [
    row("every robot on its station", P.APPROACH, 5.0, [ON, ON], [1, 1], cue=Cue.ON_ENVELOPE),
    row("one robot still on its way", P.APPROACH, 5.0, [ON, OFF], [1, 1]),
    row("on station, a detour still on", P.APPROACH, 5.0, [ON, ON], [1, 1], detouring=True),
    row("the approach times out", P.APPROACH, S.timeout + 1, [ON, OFF], [1, 1], reason="timeout"),
    row("every robot touching", P.CLOSE_IN, 5.0, [0, 0], [TOUCH, TOUCH], cue=Cue.ALL_TOUCHING),
    row("one robot not yet touching", P.CLOSE_IN, 5.0, [0, 0], [TOUCH, APART]),
    row("held through hold_s", P.HOLD, HOLD_AT + S.hold_s, [0, 0], [TOUCH, TOUCH], cue=Cue.HELD),
    row("not yet hold_s", P.HOLD, HOLD_AT + 0.5 * S.hold_s, [0, 0], [TOUCH, TOUCH]),
    row(
        "a gap opens in the hold", P.HOLD, HOLD_AT + 0.1, [0, 0], [TOUCH, RELEASED],
        cue=Cue.CONTACT_LOST, kinds=["contact_lost"],
    ),
    row(
        "the object slips away in the hold", P.HOLD, HOLD_AT + 0.1, [0, 0], [TOUCH, TOUCH],
        moved=2 * S.hold_tolerance, cue=Cue.ESCAPED, kinds=["escape"],
    ),
    row(
        "arrested and settled (a capture alone)", P.ARRESTED, ARREST_AT + S.settle_s, [0, 0],
        [TOUCH, TOUCH], cue=Cue.SETTLED,
    ),
    row(
        "arrested, a gap opens", P.ARRESTED, ARREST_AT + 0.1, [0, 0], [TOUCH, RELEASED],
        cue=Cue.CONTACT_LOST, kinds=["contact_lost"],
    ),
    row(
        "arrested, the object pushes on (no escape once arrested)", P.ARRESTED, ARREST_AT + 0.1,
        [0, 0], [TOUCH, TOUCH], moved=2 * S.hold_tolerance,
    ),
]  # fmt: skip


@pytest.mark.parametrize(("phase", "t", "dist", "gap", "moved", "detouring", "want"), CAPTURE)
def test_the_capture_reports_what_it_measures(phase, t, dist, gap, moved, detouring, want):
    st = CaptureState(
        t0=0.0,
        contact_t=np.array([1.0, 1.5]),
        hold_t0=HOLD_AT,
        hold_polygon=SQUARE,
        arrest_t=ARREST_AT,
    )
    m = Measures(
        t, np.array(dist, float), np.zeros((2, 2)), np.array(gap, float), SQUARE + [moved, 0.0],
        detouring,
    )  # fmt: skip
    rep = advance(st, m, S, phase)
    cue, reason, kinds = want
    assert rep.cue == cue
    assert (rep.failure.reason if rep.failure else None) == (Reason(reason) if reason else None)
    assert [e.kind for e in rep.events] == kinds
    if cue == Cue.ALL_TOUCHING:  # the hold starts here, from the polygon it saw
        assert rep.state.hold_t0 == t and np.array_equal(rep.state.hold_polygon, m.polygon)
    if cue in (Cue.CONTACT_LOST, Cue.ESCAPED):  # counted, the cage let go
        assert rep.state.releases + rep.state.escapes == 1 and rep.state.cage is None


# ------------------------------------------------------------------ the roster
def _view(t, present, stale):
    n = len(present)
    return FleetView(
        t, tuple(f"r{i + 1}" for i in range(n)), np.zeros((n, 3)), np.zeros((n, 3)),
        np.asarray(stale, bool), np.asarray(present, bool), np.zeros(3), np.zeros(3), None, False,
    )  # fmt: skip


# (the robot's liveliness, stale since (s before the tick, None: fresh), carrying) → gone
ROSTER = [
    ("present and fresh", True, None, False, False),
    ("its liveliness gone", False, None, False, True),
    ("stale, not yet long", True, 0.5 * LOST_STALE_S, False, False),
    ("stale too long while capturing", True, LOST_STALE_S, False, True),
    ("stale too long while carrying: it keeps its contact", True, 10 * LOST_STALE_S, True, False),
    ("its liveliness gone while carrying", False, None, True, True),
]


@pytest.mark.parametrize(
    ("why", "present", "stale_for", "carrying", "gone"), ROSTER, ids=[r[0] for r in ROSTER]
)
def test_the_roster_says_who_is_gone(why, present, stale_for, carrying, gone):
    roster = Roster(2)
    t = 100.0
    stale = [stale_for is not None, False]
    if stale_for is not None:
        roster.gone(_view(t - stale_for, [True, True], stale), carrying)  # it turned stale then
    got = roster.gone(_view(t, [present, True], stale), carrying)
    assert got.tolist() == [gone, False]
    assert roster.silent[0] == (gone and present)  # gone with its liveliness up: silent


def test_the_roster_loses_a_robot_once_and_takes_it_back_when_it_returns():
    roster = Roster(3)
    gone = np.array([False, True, False])
    idx, events, replan = roster.losses(
        _view(1.0, [1, 0, 1], [0] * 3), gone, np.array([1, 2]), "approach"
    )
    assert idx == [1] and replan and [(e.robot, e.assigned) for e in events] == [("r2", True)]
    idx, events, _ = roster.losses(
        _view(1.1, [1, 0, 1], [0] * 3), gone, np.array([1, 2]), "approach"
    )
    assert idx == [] and events == []  # once
    # while carrying the event does not say whether it held a capture point
    _, events, replan = roster.losses(_view(1.2, [1, 1, 0], [0] * 3), ~gone, None, "transport")
    assert [(e.robot, e.assigned) for e in events] == [("r1", None), ("r3", None)] and not replan
    back = roster.joins(_view(2.0, [1, 1, 1], [0] * 3), np.zeros(3, bool))
    assert [e.robot for e in back] == ["r1", "r2", "r3"] and roster.available.all()
    assert roster.lost == [1, 0, 2]


# ------------------------------------------------------------------ the outage watch
# ticks of (t, robots gone) → (lost at that tick, paused, event kinds)
OUTAGE = [
    (
        "one robot's liveliness gone: lost at once",
        [(0.0, [1, 0, 0])],
        [(0.0, [0], False, [])],
    ),
    (
        "two gone at once, back within the grace: one outage, nobody lost",
        [(0.0, [1, 1, 0]), (1.0, [1, 1, 0]), (1.5, [0, 0, 0])],
        [(0.0, [], True, ["outage"]), (1.0, [], True, []), (1.5, [], False, ["outage_end"])],
    ),
    (
        "two gone past the grace: the ones still missing are lost",
        [(0.0, [1, 1, 0]), (1.0, [0, 1, 0]), (2.5, [0, 1, 0])],
        [(0.0, [], True, ["outage"]), (1.0, [], True, []), (2.5, [1], False, ["outage_end"])],
    ),
]


@pytest.mark.parametrize(("why", "ticks", "want"), OUTAGE, ids=[o[0] for o in OUTAGE])
def test_the_outage_watch_pauses_for_a_fleet_wide_silence(why, ticks, want):
    watch = OutageWatch(grace=2.0)
    relied = np.ones(3, bool)
    for tick, (t, lost, paused, kinds) in zip(ticks, want, strict=True):
        gone, pause, events = watch.filter(
            tick[0], np.array(tick[1], bool), relied, ("a", "b", "c")
        )
        assert tick[0] == t and np.flatnonzero(gone).tolist() == lost
        assert pause == paused and [e.kind for e in events] == kinds


def test_a_lone_silent_robot_waits_a_window_for_others():
    watch = OutageWatch(grace=2.0, window=0.5)
    one = np.array([True, False, False])
    gone, pause, _ = watch.filter(0.0, one, np.ones(3, bool), ("a", "b", "c"), silent=one)
    assert not gone.any() and not pause  # may be the first of a fleet-wide silence
    gone, pause, _ = watch.filter(0.5, one, np.ones(3, bool), ("a", "b", "c"), silent=one)
    assert gone.tolist() == [True, False, False] and not pause  # alone: lost


# ------------------------------------------------------------------ the route progress
def _progress():
    cfg = make_config(transport=True)
    o = cfg.object
    model = ObjectModel.build(cfg.object_polygon(), o.mass, o.floor_friction, 0.0, 0.1)
    way = RouteProgress(model, np.array([4.0, 0.0, 0.0]), ProgressSettings(stall_timeout=10.0))
    wp = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
    way.begin(SimpleNamespace(waypoints=wp, subgoals=wp[1:]), t=0.0)
    return way


# (the object's pose) → (subgoal reached, off the corridor)
PROGRESS = [
    ("at the start", [0.0, 0.0, 0.0], False, False),
    ("at the first subgoal", [1.95, 0.02, 0.0], True, False),
    ("at it but turned", [1.95, 0.0, math.radians(20)], False, False),
    ("beside the route, within the corridor", [1.0, 0.3, 0.0], False, False),
    ("off the corridor", [1.0, 0.6, 0.0], False, True),
]


@pytest.mark.parametrize(("why", "pose", "reached", "off"), PROGRESS, ids=[p[0] for p in PROGRESS])
def test_the_route_progress_reads_the_pose(why, pose, reached, off):
    way = _progress()
    pose = np.array(pose)
    assert way.subgoal_reached(pose) == reached and way.off_route(pose) == off


def test_the_stall_clock_runs_without_progress_and_waits_for_a_pause():
    way = _progress()
    start = np.zeros(3)
    assert way.stalled(0.0, start) == ("", True)  # the first measure is progress
    assert way.stalled(9.0, start)[0] == ""
    way.pause(5.0)  # an outage or a re-arrangement: the clock waits
    assert way.stalled(14.0, start)[0] == ""
    assert way.stalled(15.5, start)[0].startswith("no progress for 10 s")
    moved = way.stalled(16.0, np.array([0.5, 0.0, 0.0]))
    assert moved == ("", True) and way.progress_t == 16.0  # progress resets it


# ------------------------------------------------------------------ the re-arrangement's counts
def test_the_rearranger_counts_futile_sets_until_the_object_moves():
    cfg = make_config(transport=True)
    o = cfg.object
    model = ObjectModel.build(cfg.object_polygon(), o.mass, o.floor_friction, 0.0, 0.1)
    slow = DeferredPlanners({"rearrange": 10**6}, 0.05)  # the sets never come in this test
    r = Rearranger(cfg, model, 0.1, "sa", 1.2, slow, np.random.default_rng(0))
    for k, t in enumerate((1.0, 2.0, 3.0), start=1):
        r.ask(t, np.array([1.0, 0.0, 0.0]), [0, 1, 2])
        assert (r.count, r.futile, r.since) == (k, k, t) and r.pending and r.take(t) is None
    r.pause(4.0)  # an outage: its timeout waits
    assert r.since == 7.0
    r.progressed()
    assert (r.count, r.futile) == (3, 0)


# ------------------------------------------------------------------ the e-stop holds the job
OPEN_SCENARIO = Scenario("open", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0))


def _held(view, estop: bool):
    return dataclasses.replace(view, estop=estop)


def test_an_estop_before_the_start_keeps_the_job_from_starting():
    """A lab brought up with the e-stop engaged: the job stays in ``plan`` (nothing is planned
    against robots that cannot move) and starts at the resume."""
    cfg = make_config()
    job = CaptureJob(cfg, np.random.default_rng(0))
    poses = np.array([r.start for r in cfg.robots], float)
    obj = np.asarray(cfg.object.start, float)
    for k in range(200):  # 10 s held
        out = job.plan(_held(tview(cfg, 0.05 * k, poses, obj), True))
        assert out.command.stop and out.report.phase == P.PLAN
    out = job.plan(tview(cfg, 10.0, poses, obj))
    assert job.phase == P.APPROACH and not out.command.stop


def test_an_estop_in_the_approach_is_a_pause_not_a_stuck_fleet():
    """An operator's e-stop for 30 s during the approach, the object at rest: the robots held
    still are not stuck (8 s) and no pinned re-plan is asked; the approach's timeout does not
    count the pause either. (A lab run failed ``pinned`` under an e-stop this way.)"""
    cfg = make_config({"object": {"motion": {"kind": "static"}}})
    job = CaptureJob(cfg, np.random.default_rng(0))
    poses = np.array([r.start for r in cfg.robots], float)
    obj = np.asarray(cfg.object.start, float)
    job.plan(tview(cfg, 0.0, poses, obj))
    assert job.phase == P.APPROACH
    t0 = job.inner.state.t0
    for k in range(1, 601):  # 30 s held, nobody moves
        out = job.plan(_held(tview(cfg, 0.05 * k, poses, obj), True))
        assert out.command.stop and not out.report.outcome.failed
    out = job.plan(tview(cfg, 30.05, poses, obj))
    assert job.phase == P.APPROACH and not out.report.outcome.failed
    assert not job._replan_job.pending and job.reach.replans == 0
    assert job.inner.state.t0 == pytest.approx(t0 + 30.0)  # the timeout waited


def test_an_estop_in_the_carry_stops_no_stall_clock():
    """Held longer than the re-arrangement's timeout mid-carry: on the resume the same
    re-arrangement goes on (its timeout waited; the stall clock waits the same way)."""
    job, cfg, poses = carry_job(OPEN_SCENARIO)
    obj = np.asarray(cfg.object.start, float)
    job.plan(tview(cfg, 0.0, poses, obj))
    m = job.transport
    assert job.phase == P.REARRANGE  # nobody holds the crate here: a set is asked for
    since, count = m.rearranger.since, m.rearranger.count
    held = 3 * m.s.stall_timeout  # longer than the re-arrangement's timeout too
    for k in range(1, int(held / 0.05) + 1):
        job.plan(_held(tview(cfg, 0.05 * k, poses, obj), True))
    out = job.plan(tview(cfg, held + 0.05, poses, obj))
    assert not out.report.outcome.failed and job.phase == P.REARRANGE
    assert m.rearranger.count == count and m.rearranger.since == pytest.approx(since + held)
