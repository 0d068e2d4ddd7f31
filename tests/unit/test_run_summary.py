"""The typed run summary (issue 21 item 6): ``RunSummary.to_json()`` is the ``fleet run --json``
object, every field the docs list (docs/getting-started.md), in the order the dict always had;
the mission summaries merge flat as ``summary()`` dicts did; the outcome (status, reason,
phase) follows the failure."""

from __future__ import annotations

import re

from controller.events import Reason
from controller.mission.summary import (
    CapturePlanSummary,
    CaptureSummary,
    JobSummary,
    TransportSummary,
    summary_of,
)
from controller.runtime.summary import (
    Checks,
    RunFailure,
    RunFigures,
    RunSummary,
    TransportFigures,
)
from tests.support.config import ROOT

CAPTURE = CaptureSummary("arrested", 0.75, 16.0, 0.01, 0, 1, 3)
TRANSPORT = TransportSummary("done", 2.2, 0, 2, 5, 48, 2.4, None)
PLAN = CapturePlanSummary(6, 5.1, True, 1.2, 2, ["r1"], 0, 0, 0, [], 0, 0)


def figures(transport: TransportFigures, mission: JobSummary) -> RunFigures:
    return RunFigures(
        mission_phase="done", done=True, failed=False, estop=False, arrest_declared=True,
        arrest_time_s=16.0, arrival_spread_s=mission.arrival_spread_s,
        contact_gaps_at_arrest_m={"r1": 0.004}, hold_displacement_m=0.02,
        phases=[{"phase": "approach", "t": 0.0}], object_gave_up_at_s=None, sim_time_s=40.0,
        ticks=800, input_timeouts=0, node={"ticks": 800}, bad_payloads=0, drops={},
        estimator={}, final_object_pose=[1.0, 2.0, 0.0],
        rearrangements=mission.rearrangements, relocations=mission.relocations,
        plan_latency_s={}, transport=transport, mission=mission,
        timing={"step_ms": {"median": 1.0}},
    )  # fmt: skip


CHECKS = Checks(0.05, 0.0, [], None, 0, 0, 0, 0, 12.5, "run.mcap", 9000)


def readme_run_fields() -> list[str]:
    """The ``fleet run --json`` fields the docs list in prose (docs/getting-started.md, "Reading
    the outcome"; not the mission's stage timings; the generated reference lists them all)."""
    text = (ROOT / "docs" / "getting-started.md").read_text()
    para = text[text.index("`fleet run --json` fields:") : text.index("`fleet replay --json` rep")]
    para = re.sub(r"`mission` \(.*?\);", "`mission`;", para, flags=re.S)
    return [w for w in re.findall(r"`([a-z_]+)`", para) if w != "ok"]


def test_every_field_the_readme_lists_is_in_the_json():
    mission = JobSummary(PLAN, CAPTURE, TRANSPORT)
    carried = TransportFigures(True, 0.1, 0.6, 80.0, 2.2, 2.3, 0.02, 0.05, 2.0, 4.0, 90.0, 0.3,
                               carried=True)  # fmt: skip
    run = RunSummary(figures(carried, mission), CHECKS, [], True, None).to_json()
    listed = readme_run_fields()
    assert len(listed) > 40 and not set(listed) - set(run), set(listed) - set(run)
    assert run["status"] == "ok" and run["phase"] == "done" and run["failure"] is None
    assert run["arrival_spread_s"] == 0.75 and run["relocations"] == 5
    # the mission's summary and its stage timings, one flat object
    assert run["mission"] == {**PLAN.to_json(), **CAPTURE.to_json(), **TRANSPORT.to_json(),
                              "step_ms": {"median": 1.0}}  # fmt: skip
    # today's order: the run's figures, the transport's, the mission, the checks, the outcome
    keys = list(run)
    assert keys[:2] == ["mission_phase", "done"]
    assert keys[-6:] == ["verdict", "arrested", "failure", "reason", "status", "phase"]
    assert keys.index("plan_latency_s") < keys.index("transported") < keys.index("mission")
    assert keys.index("mission") < keys.index("min_clearance_m") < keys.index("verdict")


def test_without_a_carry_only_transported_is_reported():
    for goal, want in ((False, {"transported": None}), (True, {"transported": False})):
        tf = TransportFigures(transported=False if goal else None)
        assert tf.to_json() == want
        run = RunSummary(figures(tf, JobSummary()), CHECKS, [], False, None).to_json()
        assert "goal_error_m" not in run and run["transported"] is want["transported"]


def test_a_failure_sets_status_reason_and_phase():
    fail = RunFailure(Reason.STALLED, 31.5, "no progress for 10 s")
    run = RunSummary(figures(TransportFigures(), JobSummary()), CHECKS, [], False, fail)
    assert not run.ok and run.status == "failed" and run.reason is Reason.STALLED
    out = run.to_json()
    assert out["failure"] == {"reason": "stalled", "t": 31.5, "detail": "no progress for 10 s"}
    assert (out["status"], out["reason"], out["phase"]) == ("failed", "stalled", "failed")


def test_the_job_summary_merges_flat_as_the_dicts_did():
    assert JobSummary().to_json() == {}
    assert JobSummary(transport=TRANSPORT).to_json() == TRANSPORT.to_json()  # entered at route
    whole = JobSummary(PLAN, CAPTURE, TRANSPORT).to_json()
    assert list(whole) == [*PLAN.to_json(), *CAPTURE.to_json(), *TRANSPORT.to_json()]
    assert whole["transport_phase"] == "done" and whole["capture_points"] == 6


def test_a_mission_without_a_summary_reports_nothing():
    class Bare:
        pass

    class CaptureOnly:
        def summary(self):
            return CAPTURE

    assert summary_of(Bare()) == JobSummary()
    got = summary_of(CaptureOnly())
    assert got.capture == CAPTURE and got.arrival_spread_s == 0.75 and got.relocations is None
