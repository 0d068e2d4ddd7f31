"""A run's outcome in words (issue 30 item 5): the verdict line names what became of the job
(delivered, arrested, the failure's reason, time and detail), the table gives rounded figures
with units and the limits beside the safety ones, the next steps name the commands to run.
Hand-built dicts shaped like ``fleet run --json``, ``fleet replay --json`` and the daemon's."""

from __future__ import annotations

import re

from controller.outcome import metres, next_steps, outcome_table, sig, verdict_line

DELIVERED = {
    "status": "ok",
    "phase": "done",
    "mission_phase": "done",
    "failure": None,
    "reason": None,
    "arrested": True,
    "arrest_time_s": 16.05,
    "contact_gaps_at_arrest_m": {"r4": 0.005492094744629028, "r5": 0.0009903124494509002},
    "hold_displacement_m": 0.0026639031513705793,
    "transported": True,
    "goal_error_m": 0.13106703799044683,
    "goal_error_deg": 0.602531195055018,
    "transport_time_s": 118.4,
    "contact_force_mean_n": 3.4567,
    "contact_impulse_ns": 1234.5678,
    "min_clearance_m": 0.04227083467230428,
    "safety_margin_m": 0.05,
    "goal_tolerance_m": 0.2,
    "goal_tolerance_deg": 10.0,
    "max_object_penetration_m": 0.0,
    "obstacle_contacts": [],
    "verdict": [],
    "sim_time_s": 109.3,
    "wall_time_s": 64.2,
    "log": "/tmp/runs/fleet-run.mcap",
}

ARRESTED = {
    "status": "ok",
    "phase": "done",
    "arrested": True,
    "arrest_time_s": 16.05,
    "transported": None,
    "sim_time_s": 16.55,
    "wall_time_s": 12.0,
}

NO_ROUTE = (
    "start pose collides: the object there comes within 0.000 m of obstacles[1] "
    "(the route needs 0.050 m of clearance: approach.safety_margin); move the object or the "
    "obstacle, or lower transport.clearance " + "and more words " * 20
)

FAILED = {
    "status": "failed",
    "phase": "failed",
    "mission_phase": "route",
    "reason": "no_route",
    "failure": {"reason": "no_route", "t": 35.2, "detail": NO_ROUTE},
    "arrested": True,
    "arrest_time_s": 20.1,
    "transported": False,
    "sim_time_s": 35.2,
    "wall_time_s": 30.0,
    "log": "/tmp/runs/fleet-run.mcap",
}


def numbers(text: str) -> list[str]:
    return re.findall(r"-?\d+(?:\.\d+)?", text)


def test_figures_are_rounded_with_units():
    assert sig(0.042270834) == "0.0423" and sig(109.3) == "109" and sig(16.05) == "16.1"
    assert sig(1234.5) == "1234" and sig(0.0) == "0" and "e" not in sig(1.5e-7)
    assert metres(0.005492094744629028) == "5.5 mm" and metres(0.13106703) == "0.131 m"


def test_a_delivered_run():
    line = verdict_line(DELIVERED)
    assert line.startswith("DELIVERED") and "\n" not in line
    assert "0.131 m" in line and "0.6°" in line and "from the goal" in line
    assert "109 s of sim time in 64.2 s" in line
    table = outcome_table(DELIVERED)
    # per-robot figures compact, in mm; no Python reprs, no 16-digit floats
    assert "r4 5.5 mm, r5 0.99 mm" in table
    assert "{" not in table and "'" not in table
    gaps = outcome_table({"contact_gaps_at_arrest_m": {"r10": 0.02, "r2": 0.001, "r1": 0.0}})
    assert "r1 0 m, r2 1 mm, r10 0.02 m" in gaps  # in the robots' order
    assert all(len(n.replace("-", "").replace(".", "").lstrip("0")) <= 4 for n in numbers(table))
    # the safety figure beside its margin, and the word when it is under it
    row = next(ln for ln in table.splitlines() if "min_clearance_m" in ln)
    assert "0.0423 m" in row and "margin 0.05 m" in row and "UNDER" in row
    assert re.search(r"goal_error_m\s+0\.131 m \(tolerance 0\.2 m: ok\)", table)
    assert "0.6°" in table and "118 s" in table and "3.46 N" in table and "1235 N·s" in table
    assert re.search(r"max_object_penetration_m\s+0 m \(limit 0\.01 m: ok\)", table)
    assert re.search(r"obstacle_contacts\s+none", table)
    assert re.search(r"verdict\s+clean", table)


def test_a_clearance_over_the_margin_is_ok_and_an_overlap_is_a_collision():
    ok = outcome_table({**DELIVERED, "min_clearance_m": 0.0562})
    assert "0.0562 m (margin 0.05 m: ok)" in ok
    hit = outcome_table({**DELIVERED, "min_clearance_m": -0.003})
    assert "-3 mm" in hit and "COLLISION" in hit


def test_an_arrest_without_a_goal():
    line = verdict_line(ARRESTED)
    assert line.startswith("ARRESTED at 16.1 s") and "no goal set" in line
    assert "16.6 s of sim time" in line
    table = outcome_table(ARRESTED)
    assert "arrest_time_s" in table and "16.1 s" in table
    assert "transported" not in table  # no goal: nothing to say about a transport


def test_a_failure_names_its_reason_time_and_detail_on_one_line():
    line = verdict_line(FAILED)
    assert line.startswith("FAILED no_route at 35.2 s: start pose collides")
    assert "obstacles[1]" in line and "0.000 m" in line
    assert "\n" not in line and len(line) < 250 and "…" in line
    table = outcome_table(FAILED)
    row = next(ln for ln in table.splitlines() if ln.strip().startswith("failure"))
    assert "no_route at 35.2 s" in row and "lower transport.clearance" in row
    assert re.search(r"transported\s+no", table)
    steps = next_steps({**FAILED, "config": "lab.toml"}, FAILED["log"])
    assert any("fleet plan route --config lab.toml" in s for s in steps)


def test_a_lab_run_reads_in_seconds_from_its_start_not_epoch():
    t0 = 1795841900.0
    lab = {
        "t0_s": t0,
        "start_s": t0,
        "duration_s": 16.1,
        "phase": "failed",
        "mission_phase": "route",
        "failure": {"reason": "no_route", "t": t0 + 16.1, "detail": "start pose collides"},
        "arrested": True,
        "arrest_time_s": t0 + 12.3,
        "phases": [{"phase": "approach", "t": t0 + 0.1}, {"phase": "failed", "t": t0 + 16.1}],
    }
    text = verdict_line(lab) + "\n" + outcome_table(lab)
    assert "FAILED no_route at 16.1 s" in text and "12.3 s" in text
    assert "approach 0.1 s → failed 16.1 s" in text
    assert "1795" not in text
    assert "16.1 s on the wall clock" in verdict_line(lab)


def test_a_stopped_daemon_and_a_log_that_ends_mid_job():
    daemon = {"stopped": "interrupted", "phase": "transport", "duration_s": 40.0, "t0_s": 5.0}
    assert verdict_line(daemon).startswith("STOPPED (interrupted) in phase transport at 40.0 s")
    replay = {
        "complete": False,
        "duration_s": 22.0,
        "phases": [{"phase": "approach", "t": 0.05}, {"phase": "close_in", "t": 11.7}],
    }
    line = verdict_line(replay)
    assert line.startswith("STOPPED (the log ends) in phase close_in")
    assert "cut short" in line


def test_missing_keys_give_what_is_known():
    assert verdict_line({}).startswith("STOPPED")
    assert outcome_table({}) == ""
    assert verdict_line({"status": "failed"}).startswith("FAILED")
    assert verdict_line({"phase": "done", "status": "ok"}).startswith("DONE")
    minimal = {"min_clearance_m": None, "contact_gaps_at_arrest_m": None, "verdict": None}
    assert outcome_table(minimal) == ""
    steps = next_steps({}, None)
    assert len(steps) == 1 and "fleet log layout" in steps[0]


def test_next_steps_name_the_plots_and_the_foxglove_layout():
    steps = next_steps(DELIVERED, None)
    assert "fleet replay /tmp/runs/fleet-run.mcap --plots /tmp/runs/fleet-run-plots" in steps[0]
    assert any("fleet log layout" in s and "/tmp/runs/fleet-run.mcap" in s for s in steps)
    # the clearance under the margin: named, with where to look
    assert any("approach.safety_margin" in s and "0.0423 m" in s for s in steps)
    spaced = next_steps({}, "/tmp/my runs/a.mcap")
    assert "'/tmp/my runs/a.mcap' --plots '/tmp/my runs/a-plots'" in spaced[0]
