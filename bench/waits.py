"""Where a user waits (issue 33 item 5): the README's main job and the plans it shows first.

Prints ONE JSON object on stdout (progress on stderr). Each measured as a newcomer meets it,
in a process of its own, ``--repeats`` times interleaved (medians, and every run):

- ``run``: ``fleet run --config fleet.toml --json`` (what ``make run`` runs once set up): the
  wall time of the whole process (start-up, the dry run, the log, the verdict), the outcome's
  status and its sim time; goal: <= 45 s of wall time on an idle 2-core machine;
- ``route``: ``fleet plan route --config fleet.toml --json``: the object route's own
  ``seconds`` (C-space, the goal's cost-to-go table and the search at 128^2 x 36) and the
  process's wall time; goal: the plan < 0.3 s;
- ``capture``: ``fleet plan capture --config fleet.toml --json``: the GA's ``seconds``.

A run that is not ``ok`` is counted (``failed``) and makes the exit status 1. The 1-minute load
average at the start and the end: the machine is shared, read the figures with it.

Usage: python bench/waits.py [--repeats 3] [--config fleet.toml]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RUN_GOAL_S = 45.0
ROUTE_GOAL_S = 0.3


def _fleet(*args: str) -> tuple[float, int, dict]:
    """``fleet ARGS`` in a process of its own: (wall s, exit status, its JSON or {})."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "controller.cli", *args], cwd=ROOT, capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    try:
        out = json.loads(proc.stdout)
    except json.JSONDecodeError:
        out = {}
    return wall, proc.returncode, out


def _median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--config", default="fleet.toml")
    ns = ap.parse_args()
    cfg = str(Path(ns.config).resolve())
    load0 = os.getloadavg()[0]
    runs, routes, captures = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(ns.repeats):
            wall, code, out = _fleet("plan", "route", "--config", cfg, "--json")
            routes.append({"wall_s": wall, "exit": code, "seconds": out.get("seconds"),
                           "status": out.get("status")})  # fmt: skip
            wall, code, out = _fleet("plan", "capture", "--config", cfg, "--json")
            captures.append({"wall_s": wall, "exit": code, "seconds": out.get("seconds"),
                             "feasible": out.get("feasible")})  # fmt: skip
            log = str(Path(tmp) / f"run-{k}.mcap")
            wall, code, out = _fleet("run", "--config", cfg, "--json", "--out", log)
            keys = ("status", "sim_time_s", "transport_time_s", "goal_error_m", "goal_error_deg",
                    "arrest_time_s", "rearrangements", "relocations", "missed_ticks",
                    "watchdog_stops", "min_clearance_m", "verdict")  # fmt: skip
            runs.append({"wall_s": wall, "exit": code, **{k: out.get(k) for k in keys}})
            print(
                f"waits: {k + 1}/{ns.repeats}: run {wall:.1f} s ({out.get('status')}), route "
                f"{routes[-1]['seconds']} s",
                file=sys.stderr,
            )
    ok_runs = [r for r in runs if r["exit"] == 0 and r["status"] == "ok"]
    ok_routes = [r for r in routes if r["exit"] == 0 and r["status"] == "ok"]
    ok_captures = [r for r in captures if r["exit"] == 0 and r["feasible"]]
    run_s = _median([r["wall_s"] for r in ok_runs])
    route_s = _median([r["seconds"] for r in ok_routes])
    result = {
        "bench": "waits",
        "config": ns.config,
        "repeats": ns.repeats,
        "run": {
            "wall_s_median": run_s,
            "sim_time_s_median": _median([r["sim_time_s"] for r in ok_runs]),
            "goal_s": RUN_GOAL_S,
            "goal_met": run_s is not None and run_s <= RUN_GOAL_S,
            "failed": len(runs) - len(ok_runs),
            "runs": runs,
        },
        "route": {
            "seconds_median": route_s,
            "wall_s_median": _median([r["wall_s"] for r in ok_routes]),
            "goal_s": ROUTE_GOAL_S,
            "goal_met": route_s is not None and route_s < ROUTE_GOAL_S,
            "failed": len(routes) - len(ok_routes),
            "runs": routes,
        },
        "capture": {
            "seconds_median": _median([r["seconds"] for r in ok_captures]),
            "wall_s_median": _median([r["wall_s"] for r in ok_captures]),
            "failed": len(captures) - len(ok_captures),
            "runs": captures,
        },
        "load_avg_1m": [load0, os.getloadavg()[0]],
    }
    print(json.dumps(result, indent=1))
    failed = result["run"]["failed"] + result["route"]["failed"] + result["capture"]["failed"]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
