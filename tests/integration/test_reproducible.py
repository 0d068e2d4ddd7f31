"""The dry run is reproducible with planning off the tick: two ``fleet run --json`` of the
top-level fleet.toml (its goal brought 1.3 m from the start, so the whole job, every planner
kind included, takes a sixth of the time), the second with a CPU hog on every core beside it,
give the same outcome (the plans come after their modelled latency in sim time, whatever the
wall clock did)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import pytest

from tests.support.config import ROOT, write_toml
from tests.support.hog import cpu_hogs

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

FIELDS = ("phase", "status", "arrest_time_s", "transport_time_s", "rearrangements", "relocations")
CLOSE = ("goal_error_m", "goal_error_deg", "sim_time_s")


NEAR_GOAL = [3.3, 3.2, 0.0]


def near_config(tmp_path):
    data = tomllib.loads((ROOT / "fleet.toml").read_text())
    data["object"]["goal"] = NEAR_GOAL
    return write_toml(tmp_path / "fleet-near.toml", data)


def fleet_run(tmp_path, name: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "controller.cli", "run", "--config", str(near_config(tmp_path))]
        + ["--json", "--out", str(tmp_path / f"{name}.mcap")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=900,
    )
    assert out.returncode in (0, 1), out.stderr[-2000:]
    return json.loads(out.stdout)


def test_the_dry_run_of_fleet_toml_gives_the_same_outcome_idle_and_loaded(tmp_path):
    first = fleet_run(tmp_path, "idle")
    with cpu_hogs():
        second = fleet_run(tmp_path, "loaded")
    assert first["status"] == "ok" and first["transported"] is True, first["failure"]
    for k in FIELDS:
        assert first[k] == second[k], k
    for k in CLOSE:
        assert abs(first[k] - second[k]) <= 1e-9, k
    latency = first["plan_latency_s"]
    assert all(latency[kind]["n"] >= 1 for kind in ("route", "rearrange", "transport")), latency
    assert latency["transport"]["n"] == second["plan_latency_s"]["transport"]["n"]
    assert first["missed_ticks"] == second["missed_ticks"] == 0
