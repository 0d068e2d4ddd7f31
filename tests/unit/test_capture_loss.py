"""Robot loss and join during the capture (issue 17), tick by tick on hand-made views (no bus,
no world): an assigned robot lost mid-approach re-plans the capture over the robots left, a
spare lost is only marked unavailable, too few left fail with ``robots_lost``, a robot back is
available without its old point, and ``fleet.start_wait`` starts without a robot never seen."""

from __future__ import annotations

import numpy as np
import pytest

from controller.config import ConfigError
from controller.events import by_kind
from controller.mission.job import LOST_REPLAN_RETRIES, CaptureJob
from controller.mission.planners import InlinePlanners, PlanResult
from controller.mission.roster import LOST_STALE_S
from controller.mission.types import FleetView, Phase, step
from tests.support.config import base_config_dict, deep_update, make_config

DT = 0.05


def job(hold_force: float = 4.0, start_wait: float = 5.0) -> CaptureJob:
    cfg = make_config(
        {
            "sim": {"backend": "ideal"},
            "capture": {"hold_force": hold_force},
            "fleet": {"start_wait": start_wait},
        }
    )
    return CaptureJob(cfg)


def view(j: CaptureJob, t: float, present=None, stale=None, unseen=()) -> FleetView:
    n = j.n
    poses = np.array([r.start for r in j.cfg.robots], float)
    stale = np.zeros(n, bool) if stale is None else np.asarray(stale, bool)
    present = np.ones(n, bool) if present is None else np.asarray(present, bool)
    for i in unseen:  # never seen: no estimate, stale, no liveliness
        poses[i] = np.nan
        stale[i], present[i] = True, False
    obj = np.asarray(j.cfg.object.start, float)
    return FleetView(
        t, j.cfg.robot_ids, poses, np.zeros((n, 3)), stale, present, obj, np.zeros(3), None,
        False,
    )  # fmt: skip


def without(n: int, *gone: int) -> np.ndarray:
    out = np.ones(n, bool)
    out[list(gone)] = False
    return out


def kinds(out) -> list[str]:
    return [e.kind for e in out.events]


def started(j: CaptureJob, ticks: int = 3) -> float:
    """Start the job and run a few approach ticks; the next tick's time."""
    t = 0.0
    for _ in range(ticks):
        out = step(j, view(j, t))
        t += DT
    assert out.phase == Phase.APPROACH
    return t


def test_losing_an_assigned_robot_mid_approach_replans_over_the_robots_left():
    j = job()
    t = started(j)
    lost = int(j.assignment[0])
    out = step(j, view(j, t, present=without(j.n, lost)))
    assert kinds(out)[:2] == ["robot_lost", "capture"]
    ev = by_kind(out.events)
    assert ev["robot_lost"].to_dict() == {
        "t": t, "robot": j.cfg.robots[lost].id, "phase": "approach", "assigned": True,
    }  # fmt: skip
    assert lost not in j.assignment and len(set(j.assignment)) == len(j.assignment)
    assert ev["capture"].robots == [j.cfg.robots[i].id for i in j.assignment]
    assert j.cfg.robots[lost].id in ev["capture"].unavailable
    # the same certificates as the first plan: form closure, the hold force held
    assert j.capture.form_closure and j.capture.hold_capacity >= 1.0
    assert len(j.capture.points) <= j.n - 1
    assert out.phase == Phase.APPROACH and not out.failed
    assert np.all(out.commands[lost] == 0.0)  # a lost robot is told nothing
    summary = j.summary().plan
    assert summary.loss_replans == 1 and summary.robots_lost == [j.cfg.robots[lost].id]


class SlowFirst(InlinePlanners):
    """The capture re-plans' first ``n`` answers are a timeout (a loaded machine)."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.left = n

    def submit(self, kind, t, fn, *args):
        ticket = super().submit(kind, t, fn, *args)
        if kind == "capture" and self.left > 0:
            self.left -= 1
            self._results[ticket] = PlanResult(False, error="timeout after 10 s")
        return ticket


@pytest.mark.parametrize("timeouts", [LOST_REPLAN_RETRIES, LOST_REPLAN_RETRIES + 1])
def test_a_replan_after_a_loss_that_times_out_is_asked_again_before_failing(timeouts):
    """No answer is not "no capture": the re-plan is asked again (every robot held) and the
    approach goes on with its answer; only an answer that never comes fails robots_lost."""
    cfg = make_config({"sim": {"backend": "ideal"}, "capture": {"hold_force": 4.0}})
    j = CaptureJob(cfg, planners=SlowFirst(timeouts))
    t = started(j)
    lost = int(j.assignment[0])
    held = []
    for _ in range(LOST_REPLAN_RETRIES + 2):
        out = step(j, view(j, t, present=without(j.n, lost)))
        t += DT
        if out.failed or "capture" in kinds(out):
            break
        held.append(bool(np.all(out.commands == 0.0)))
    assert held and all(held)  # every robot held while the answer was awaited
    if timeouts <= LOST_REPLAN_RETRIES:
        assert not out.failed and "capture" in kinds(out) and out.phase == Phase.APPROACH
        assert lost not in j.assignment
    else:
        assert out.failed and out.reason == "robots_lost"
        assert "timeout after 10 s" in by_kind(out.events)["failure"].detail


def test_a_stale_robot_is_lost_only_after_the_grace():
    """A robot silent alone (its estimate stale, its liveliness up) is lost after
    ``LOST_STALE_S`` and the outage watch's window for others to follow."""
    j = job()
    t0 = started(j)
    i = int(j.assignment[1])
    stale = without(j.n, i) == 0
    t = t0
    while t - t0 < LOST_STALE_S + j.outage.window - 1e-9:
        out = step(j, view(j, t, stale=stale))
        assert "robot_lost" not in kinds(out) and np.all(out.commands[i] == 0.0)
        t += DT
    out = step(j, view(j, t, stale=stale))
    assert kinds(out)[:2] == ["robot_lost", "capture"]
    assert i not in j.assignment


def test_losing_a_spare_only_marks_it_unavailable():
    j = job(hold_force=0.0)  # the GA's 4 points: two spares
    t = started(j)
    before = j.assignment.copy()
    spare = next(i for i in range(j.n) if i not in before)
    out = step(j, view(j, t, present=without(j.n, spare)))
    assert kinds(out) == ["robot_lost"]
    assert by_kind(out.events)["robot_lost"].assigned is False
    assert np.array_equal(j.assignment, before) and not j.roster.available[spare]
    out = step(j, view(j, t + DT, present=without(j.n, spare)))
    assert "robot_lost" not in kinds(out)  # reported once


def test_losing_too_many_fails_safe_with_robots_lost():
    """Three gone at once: one outage first (the job pauses, every robot still), then, still
    gone after ``fleet.outage_grace``, they are lost and the robots left cannot close it."""
    j = job()
    t = started(j)
    gone = [int(i) for i in j.assignment[:3]]
    grace = j.cfg.fleet.outage_grace
    t_out = t
    while t - t_out < grace - 1e-9:
        out = step(j, view(j, t, present=without(j.n, *gone)))
        assert not out.failed and np.all(out.commands == 0.0)
        assert "robot_lost" not in kinds(out)
        t += DT
    out = step(j, view(j, t, present=without(j.n, *gone)))
    assert kinds(out)[0] == "outage_end"
    assert out.failed and out.reason == "robots_lost" and out.phase == Phase.FAILED
    assert np.all(out.commands == 0.0)
    detail = by_kind(out.events)["failure"].detail
    assert all(j.cfg.robots[i].id in detail for i in gone)
    assert kinds(out).count("robot_lost") == 3
    out = step(j, view(j, t + DT))  # they come back: the job stays failed, every robot stopped
    assert out.failed and out.reason == "robots_lost" and np.all(out.commands == 0.0)


def test_a_robot_back_is_available_but_never_gets_its_old_point():
    j = job()
    t = started(j)
    first = int(j.assignment[0])
    step(j, view(j, t, present=without(j.n, first)))
    for _ in range(3):  # it comes back: available, no point (nothing to chase)
        t += DT
        intent = j.plan(view(j, t))
        assert first not in j.assignment and np.all(intent.command.velocities[first] == 0.0)
        j.safety(view(j, t), intent)
    assert j.roster.available[first]
    # another assigned robot is lost: the re-plan needs five robots and may pick it again
    second = int(j.assignment[0])
    t += DT
    out = step(j, view(j, t, present=without(j.n, second)))
    assert "capture" in kinds(out) and first in j.assignment and second not in j.assignment


def test_a_robot_back_emits_joined_once():
    j = job()
    t = started(j)
    first = int(j.assignment[0])
    step(j, view(j, t, present=without(j.n, first)))
    out = step(j, view(j, t + DT))
    assert by_kind(out.events)["robot_joined"].to_dict() == {
        "t": t + DT,
        "robot": j.cfg.robots[first].id,
    }
    out = step(j, view(j, t + 2 * DT))
    assert "robot_joined" not in kinds(out)


@pytest.mark.parametrize("hold_force", [0.0, 4.0])
def test_start_wait_starts_without_a_robot_never_seen(hold_force):
    j = job(hold_force=hold_force, start_wait=1.0)
    missing = 2
    t = 0.0
    while t < 1.0 - 1e-9:
        out = step(j, view(j, t, unseen=[missing]))
        assert out.phase == Phase.PLAN and np.all(out.commands == 0.0)
        t += DT
    out = step(j, view(j, t, unseen=[missing]))
    assert out.phase == Phase.APPROACH and "capture" in kinds(out)
    assert missing not in j.assignment
    assert by_kind(out.events)["capture"].unavailable == [j.cfg.robots[missing].id]
    assert np.all(np.isfinite(out.commands)) and np.all(out.commands[missing] == 0.0)
    assert np.any(out.commands != 0.0)
    out = step(j, view(j, t + DT))  # seen at last: a spare
    assert "robot_joined" in kinds(out) and j.roster.available[missing]
    assert missing not in j.assignment


def test_every_robot_seen_starts_at_once():
    j = job(start_wait=100.0)
    out = step(j, view(j, 0.0))
    assert out.phase == Phase.APPROACH and by_kind(out.events)["capture"].unavailable == []


def test_start_wait_is_validated_with_its_key_path():
    from controller.config import parse_config

    data = deep_update(base_config_dict(), {"fleet": {"start_wait": -1.0}})
    with pytest.raises(ConfigError) as e:
        parse_config(data, "test")
    assert e.value.path == "fleet.start_wait"


def test_a_fleet_wide_silence_is_one_outage_that_the_job_rides_out():
    """Every robot's liveliness gone and its estimate stale for 1.5 s (a hub restart, a world
    stall, a network cut): one outage, the job pauses with every robot stopped, nobody is lost,
    nothing is re-planned; when they are back the approach carries on with the same points."""
    j = job()
    t = started(j)
    points, assignment = j.capture.points.copy(), j.assignment.copy()
    nobody = np.zeros(j.n, bool)
    t_out = t
    seen: list[str] = []
    while t - t_out < 1.5:
        out = step(j, view(j, t, present=nobody, stale=~nobody))
        seen += kinds(out)
        assert np.all(out.commands == 0.0) and not out.failed
        t += DT
    assert seen == ["outage"]
    out = step(j, view(j, t))
    assert kinds(out)[0] == "outage_end" and by_kind(out.events)["outage_end"].lost == []
    assert out.phase == Phase.APPROACH and np.any(out.commands != 0.0)
    assert np.array_equal(j.capture.points, points) and np.array_equal(j.assignment, assignment)
    assert j.summary().plan.robots_lost == [] and j.summary().plan.outages == 1


def test_an_outage_loses_only_the_robots_still_missing_after_its_grace():
    j = job()
    t = started(j)
    nobody = np.zeros(j.n, bool)
    first = int(j.assignment[0])
    grace = j.cfg.fleet.outage_grace
    t_out = t
    while t - t_out < grace - 1e-9:  # all gone, then all but one back within the grace
        present = nobody if t - t_out < 1.0 else without(j.n, first)
        step(j, view(j, t, present=present, stale=~present))
        t += DT
    out = step(j, view(j, t, present=without(j.n, first)))
    assert kinds(out)[:3] == ["outage_end", "robot_lost", "capture"]
    assert by_kind(out.events)["robot_lost"].robot == j.cfg.robots[first].id
    assert first not in j.assignment and j.summary().plan.loss_replans == 1


def test_a_silence_whose_robots_go_quiet_a_few_ticks_apart_is_one_outage():
    """The world stalls: one robot's last pose came 50 ms before the others' (their estimates
    turn stale apart; their liveliness stays up a while). The first one alone is not lost at
    once: the others follow within the window, and it is one outage that nobody is lost in."""
    j = job()
    t = started(j)
    first = int(j.assignment[0])
    quiet_first = without(j.n, first) == 0  # only `first` stale
    t_out = t
    seen: list[str] = []
    while t - t_out < 1.5:  # `first` stale from t_out, every robot from 2 ticks later
        stale = quiet_first if t - t_out < 2 * DT - 1e-9 else np.ones(j.n, bool)
        out = step(j, view(j, t, stale=stale))
        seen += kinds(out)
        assert not out.failed
        t += DT
    assert "robot_lost" not in seen and seen.count("outage") == 1, seen
    out = step(j, view(j, t))
    assert kinds(out)[0] == "outage_end" and by_kind(out.events)["outage_end"].lost == []
    assert j.summary().plan.robots_lost == []
