"""Planning off the tick: the mission asks, holds or executes its last plan meanwhile, and picks
the plan up when it is due (lockstep: exactly ``latency_ticks`` later, whatever the wall clock);
the lab worker hands a plan over when computed, gives a hung planner up, and a failing planner
leaves the robots stopped, never drifting."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from controller.events import by_kind
from controller.mission.guard import SafetyStage
from controller.mission.planners import DeferredPlanners, InlinePlanners, PlanSlot
from controller.mission.transport import TransportMission
from controller.mission.types import Phase, Reason
from controller.runtime.planner import PlannerWorker
from tests.support.transport_mission import holders, view
from tests.support.transport_scenarios import CRATE, Scenario, scenario_config

DT = 0.05
OPEN = Scenario("open", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0))
LIGHT = Scenario("light", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), mass=1.0, floor_friction=0.05)


def transport(planners, sc: Scenario = OPEN):
    cfg = scenario_config(sc)
    held, pts, nrm = holders(cfg)
    m = TransportMission(
        cfg, np.random.default_rng(0), SafetyStage(cfg), held, pts, nrm, planners=planners
    )
    return m, cfg, np.array([r.start for r in cfg.robots])


def test_the_robots_hold_while_the_route_is_on_its_way_and_take_it_when_due():
    ticks = {"route": 4, "rearrange": 3, "transport": 2, "capture": 1}
    m, cfg, poses = transport(DeferredPlanners(ticks, DT))
    kinds = []
    for k in range(4):
        out = m.plan(view(cfg, k * DT, poses, cfg.object.start))
        kinds += [e.kind for e in out.report.events]
        assert m.phase == Phase.ROUTE and out.command.hold is not None and out.command.hold.all()
        assert not np.any(out.command.velocities)
    assert "route" not in kinds
    out = m.plan(view(cfg, 4 * DT, poses, cfg.object.start))
    assert "route" in [e.kind for e in out.report.events]  # due at t + 4 ticks, not before
    assert m.phase in (Phase.TRANSPORT, Phase.REARRANGE)


def test_the_same_plans_come_inline_and_deferred_only_later():
    """A deferred plan is the plan computed from the state it was asked with: the same route
    as at once, only ``latency_ticks`` ticks later."""
    a, cfg, poses = transport(InlinePlanners())
    b, _, _ = transport(DeferredPlanners({"route": 3}, DT))
    a.plan(view(cfg, 0.0, poses, cfg.object.start))
    for k in range(4):
        b.plan(view(cfg, k * DT, poses, cfg.object.start))
    assert np.array_equal(a.way.route.waypoints, b.way.route.waypoints)


def test_the_last_plan_is_executed_while_the_next_one_is_computed():
    ticks = {"route": 0, "rearrange": 0, "transport": 6, "capture": 0}
    m, cfg, poses = transport(DeferredPlanners(ticks, DT), LIGHT)  # the holders can push it
    t = 0.0
    while m.pusher.last_plan is None and t < 2.0:  # the segment's first plan: held meanwhile
        out = m.plan(view(cfg, t, poses, cfg.object.start))
        if m.phase == Phase.TRANSPORT and m.pusher.last_plan is None:
            assert out.command.hold.all() and not np.any(out.command.velocities)
        t += DT
    assert m.phase == Phase.TRANSPORT and m.pusher.last_plan is not None
    first, plans = m.pusher.last_plan, m.pusher.plans
    waited = 0
    while True:  # the next plan is asked one interval on and comes 6 ticks after that
        out = m.plan(view(cfg, t, poses, cfg.object.start))
        t += DT
        waited += 1
        if m.pusher.plans > plans:
            break
        assert m.pusher.last_plan is first and np.any(
            out.command.velocities
        )  # the robots push meanwhile
    # one plan per interval, as before; each one planned from a state 6 ticks old
    assert waited == round(first.interval / DT)
    age = by_kind(out.report.events)["transport"].plan_age_s
    assert age == pytest.approx(6 * DT)


def test_a_failing_planner_stops_the_robots_with_the_reason():
    m, cfg, poses = transport(InlinePlanners())
    m._route_box.value = _Broken()
    out = m.plan(view(cfg, 0.0, poses, cfg.object.start))
    assert out.report.outcome.failed and out.command.stop and m.phase == Phase.FAILED
    failure = by_kind(out.report.events)["failure"]
    assert failure.reason == Reason.NO_ROUTE and "planner exploded" in failure.detail


class _Broken:
    def plan(self, pose):
        raise RuntimeError("planner exploded")


def test_the_lockstep_worker_hands_a_plan_over_exactly_when_due():
    w = PlannerWorker({"route": 3}, DT, lockstep=True, process=False)
    gate = threading.Event()
    try:
        slot = PlanSlot(w, "route")
        slot.request(1.0, lambda: gate.wait(5) and 42)
        gate.set()
        w._pool.submit(lambda: None).result()  # the job has finished by now
        assert slot.take(1.0 + 2 * DT) is None  # computed, but not due
        got = slot.take(1.0 + 3 * DT)
        assert got is not None and got.ok and got.value == 42
        s = w.summary()["route"]
        assert s["n"] == 1 and s["p50"] >= 0 and s["failed"] == 0
    finally:
        gate.set()
        w.close()


def test_the_lockstep_worker_waits_for_a_due_plan_and_says_so():
    w = PlannerWorker({"route": 1}, DT, lockstep=True, process=False)
    gate = threading.Event()
    seen = []
    try:
        slot = PlanSlot(w, "route")
        slot.request(0.0, lambda: gate.wait(5) and "late")
        waiter = threading.Thread(target=lambda: seen.append(slot.take(DT)))
        waiter.start()
        while not w.waiting and waiter.is_alive():
            waiter.join(0.01)
        assert w.waiting  # the tick waits for the due plan: the sim side is told
        gate.set()
        waiter.join(5)
        assert seen and seen[0].value == "late" and not w.waiting
    finally:
        gate.set()
        w.close()


def test_the_lab_worker_hands_a_plan_over_when_computed_and_gives_a_hung_one_up():
    now = [0.0]
    w = PlannerWorker(
        {"route": 2}, DT, lockstep=False, timeout=1.0, clock=lambda: now[0], process=False
    )
    gate = threading.Event()
    try:
        fast = PlanSlot(w, "rearrange")
        fast.request(0.0, lambda: 7)
        w._pool.submit(lambda: None).result()
        got = fast.take(0.0)  # ready as soon as computed, whatever the tick time
        assert got is not None and got.value == 7
        hung = PlanSlot(w, "route")
        hung.request(0.0, lambda: gate.wait(10))
        assert hung.take(0.0) is None
        now[0] = 1.5
        got = hung.take(0.0)
        assert got is not None and not got.ok and "timeout" in got.error
        assert w.summary()["route"]["timeouts"] == 1
    finally:
        gate.set()
        w.close()


@pytest.mark.parametrize("lockstep", [True, False])
def test_a_job_that_raises_is_a_failed_plan_not_a_dead_worker(lockstep):
    w = PlannerWorker({"route": 0}, DT, lockstep=lockstep, process=False)
    try:
        slot = PlanSlot(w, "route")
        slot.request(0.0, lambda: 1 / 0)
        got = None
        while got is None:
            got = slot.take(0.0)
        assert not got.ok and "ZeroDivisionError" in got.error
        slot.request(0.0, lambda: "next")
        got = None
        while got is None:
            got = slot.take(0.0)
        assert got.ok and got.value == "next"
    finally:
        w.close()


def _count(box, k):
    box.value = (box.value or 0) + k
    return box.value


def test_the_process_worker_keeps_job_owned_state_in_the_worker():
    """A box is sent once and lives in the worker process: successive jobs see what earlier
    ones left there, the mission's own box is never written (the tick and the worker share
    nothing), and the plans come back as the in-process run computes them."""
    from controller.mission.planners import JobOwned

    w = PlannerWorker({"route": 0}, DT, lockstep=True, process=True)
    box = JobOwned(10)
    try:
        slot = PlanSlot(w, "route")
        values = []
        for k in (1, 2, 3):
            slot.request(0.0, _count, box, k)
            values.append(slot.take(0.0).value)
        assert values == [11, 13, 16]
        assert box.value == 10
        inline = JobOwned(10)
        assert [_count(inline, k) for k in (1, 2, 3)] == values
    finally:
        w.close()


def _die_once(marker: str, box, k):
    """Kill the worker process the first time (a planner crashing its interpreter: a segfault
    in a solver, an out-of-memory kill); add ``k`` to the box the next."""
    import os
    from pathlib import Path

    if not Path(marker).exists():
        Path(marker).write_text("died")
        os._exit(1)
    return _count(box, k)


def _always_die():
    import os

    os._exit(1)


@pytest.mark.e2e  # worker processes started, killed and started again: not the fast tier
@pytest.mark.parametrize("lockstep", [True, False])
def test_a_dead_planner_worker_is_restarted_and_its_plan_run_again(tmp_path, lockstep):
    """A planner that kills its worker process does not end the job: the worker is restarted,
    the plan runs again there (from the mission's own copy of what the dead worker held), the
    next plans go on, the restart is counted; one that kills it every time is a failed plan."""
    from controller.mission.planners import JobOwned

    w = PlannerWorker({"route": 0}, DT, lockstep=lockstep, process=True, timeout=60.0)
    box = JobOwned(10)
    try:
        slot = PlanSlot(w, "route")

        def take():
            got = None
            while got is None:
                got = slot.take(0.0)
            return got

        slot.request(0.0, _count, box, 1)
        assert take().value == 11  # the worker's copy holds 11 now
        slot.request(0.0, _die_once, str(tmp_path / "died"), box, 2)
        got = take()
        assert got.ok and got.value == 12  # the rerun starts from the mission's box (10)
        slot.request(0.0, _count, box, 3)
        assert take().value == 15  # the new worker keeps its state again
        assert w.generation == 1 and w.summary()["route"]["restarts"] == 1
        slot.request(0.0, _always_die)
        got = take()
        assert not got.ok and "died" in got.error
        slot.request(0.0, _count, box, 1)
        assert take().ok  # and the worker after that one serves on
    finally:
        w.close()


def _mark_and_sleep(path: str, seconds: float) -> None:
    """A plan that says it started (a file), then runs long."""
    import time
    from pathlib import Path

    Path(path).write_text("started")
    time.sleep(seconds)


_CLOSE_SCRIPT = """
import sys, time
from pathlib import Path
from controller.runtime.planner import PlannerWorker
from tests.unit.test_planners import _mark_and_sleep
from tests.support.wait import wait_for
mark = Path(sys.argv[1])
w = PlannerWorker({"route": 0}, 0.05, lockstep=False, process=True, timeout=60.0)
w.submit("route", 0.0, _mark_and_sleep, str(mark), 30.0)
wait_for(mark.exists, 30, "the plan under way")
w.close()
print("closed", flush=True)
"""


@pytest.mark.e2e  # a worker process started and ended: not the fast tier
def test_closing_the_worker_mid_plan_ends_at_once_without_a_traceback(tmp_path):
    """A daemon that ends while a plan runs (Ctrl-C during a transport plan) exits at once,
    its worker gone, and prints no traceback from the process pool at the interpreter's exit."""
    import subprocess
    import sys
    import time

    from tests.support.config import ROOT

    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-c", _CLOSE_SCRIPT, str(tmp_path / "started")], cwd=ROOT,
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    took = time.monotonic() - t0
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "closed"
    assert "Traceback" not in proc.stderr and "Error" not in proc.stderr, proc.stderr
    assert took < 15.0, took  # not the 30 s plan's end
