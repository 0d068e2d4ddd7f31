"""``fleet daemon``'s end (issue 30 item 5): a failed lab job names the phase it failed in, the
reason and the failure's detail, with times from the job's start (the daemon ticks on the wall
clock: epoch seconds), in its log line and in the verdict it prints."""

from __future__ import annotations

import logging

import numpy as np

from controller.events import ArrestEvent, DeliveredEvent, FailureEvent, Reason
from controller.mission.types import MissionOutput, Phase
from controller.outcome import outcome_table, verdict_line
from controller.runtime.daemon import log_end
from controller.runtime.job_record import JobRecord
from tests.support.config import make_config

T0 = 1795841900.0  # an epoch: the daemon's clock
DETAIL = "start pose collides: the object there comes within 0.000 m of obstacles[1]"


def out(phase: str, events=(), **kw) -> MissionOutput:
    return MissionOutput(np.zeros((6, 3)), phase, list(events), **kw)


def arrest(t: float) -> ArrestEvent:
    return ArrestEvent(t=t, arrival_spread_s=0.8, hold_s=2.0, hold_displacement_m=0.01, gaps_m=[])


class NoSummary:
    """A mission without a summary of its own."""


def test_a_failed_lab_job_names_its_reason_detail_and_phase_from_its_start(caplog):
    cfg = make_config(transport=True)
    job = JobRecord(cfg, T0)
    job.tick(T0 + 0.1, out(Phase.APPROACH))
    job.tick(T0 + 16.1, out(Phase.ARRESTED, [arrest(T0 + 16.1)]))
    job.tick(T0 + 20.0, out(Phase.ROUTE))
    fail = FailureEvent(reason=Reason.NO_ROUTE, t=T0 + 35.2, detail=DETAIL)
    job.tick(T0 + 35.2, out(Phase.FAILED, [fail], failed=True, reason="no_route"))
    caplog.set_level(logging.INFO, logger="controller.runtime.daemon")
    log_end(job)
    (line,) = [r.getMessage() for r in caplog.records]
    assert "mission failed in phase route: no_route at 35.2 s" in line and DETAIL in line
    assert caplog.records[0].levelno == logging.ERROR
    s = job.summary(NoSummary(), "interrupted", T0 + 36.0, log="/tmp/lab.mcap")
    verdict = verdict_line(s)
    assert verdict.startswith("FAILED no_route at 35.2 s: start pose collides")
    assert "obstacles[1]" in verdict and "36 s on the wall clock" in verdict
    table = outcome_table(s)
    assert "16.1 s" in table and "approach 0.1 s → arrested 16.1 s → route 20.0 s" in table
    assert "1795" not in verdict + table
    assert "transported" in table  # the goal was set and not reached


def test_a_delivered_and_a_stopped_lab_job():
    cfg = make_config(transport=True)
    goal = list(cfg.object.goal)
    job = JobRecord(cfg, T0)
    job.tick(T0 + 1.0, out(Phase.TRANSPORT))
    at_goal = DeliveredEvent(t=T0 + 41.0, pose=[goal[0] + 0.03, goal[1] + 0.04, goal[2]])
    job.tick(T0 + 41.0, out(Phase.DONE, [at_goal], done=True))
    s = job.summary(NoSummary(), "interrupted", T0 + 41.5)
    assert s["goal_error_m"] == 0.05 or abs(s["goal_error_m"] - 0.05) < 1e-9
    assert verdict_line(s).startswith("DELIVERED 0.05 m / 0.0° from the goal after 40 s")
    stopped = JobRecord(cfg, T0)
    stopped.tick(T0 + 1.0, out(Phase.TRANSPORT))
    s = stopped.summary(NoSummary(), "interrupted", T0 + 40.0)
    assert verdict_line(s).startswith("STOPPED (interrupted) in phase transport at 40.0 s")
