"""Arrest benchmark (JSON on stdout): the seeded arrest suite in pybullet with the object alive
through the hold (walls, corners, fast, evasive, concave), the hold displacement distribution
from ground truth, and the speed edge: the highest object speed arrested in open space by six
omni robots of 0.5 m/s.

    python bench/arrest.py [--only NAME ...] [--no-edge] [--speeds 0.3,0.35,...]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controller.mission.factory import build_mission  # noqa: E402
from controller.runtime.dry_run import DryRun  # noqa: E402
from tests.support.arrest_scenarios import (  # noqa: E402
    OPEN,
    OPEN_STARTS,
    RECT,
    SCENARIOS,
    ArrestScenario,
    arrest_config,
)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run_one(sc: ArrestScenario, out_dir: Path) -> dict:
    cfg = arrest_config(sc)
    t0 = time.perf_counter()
    res = DryRun(cfg, build_mission(cfg), out_dir / f"{sc.name}.mcap", max_time=sc.max_time).run()
    reason = (res.get("failure") or {}).get("reason")
    outcome = "arrest" if res.get("arrested") else reason
    row = {
        "name": sc.name,
        "expect": sc.expect,
        "outcome": outcome,
        "as_expected": outcome in sc.expect,
        "wall_replans": (res.get("mission") or {}).get("wall_replans"),
        "reassignments": (res.get("mission") or {}).get("reassignments"),
        "status": res.get("status"),
        "arrest_time_s": res.get("arrest_time_s"),
        "hold_displacement_m": res.get("hold_displacement_m"),
        "max_contact_gap_at_arrest_m": (
            max(res["contact_gaps_at_arrest_m"].values())
            if res.get("contact_gaps_at_arrest_m")
            else None
        ),
        "failure": res.get("failure"),
        "min_clearance_m": res.get("min_clearance_m"),
        "phases": [p["phase"] for p in res.get("phases", [])],
        "wall_s": round(time.perf_counter() - t0, 2),
    }
    log(f"{sc.name}: {outcome} (expect {sc.expect}) {row['wall_s']} s wall")
    return row


def speed_edge(speeds: list[float], out_dir: Path) -> dict:
    """Highest line speed arrested in open space (6 omni robots at 0.5 m/s), over two headings:
    an arrest counts only if it came before the object reached a wall (no wall re-plan)."""
    rows = []
    for v in speeds:
        ok = 0
        for k, heading in enumerate((0.3, -0.6)):
            sc = ArrestScenario(
                f"edge-{v:.2f}-{k}",
                RECT,
                (5.0, 5.0 if heading > 0 else 11.0, 0.0),
                {"kind": "line", "speed": v, "heading": heading},
                kinds="oooooo",
                max_speed=0.5,
                seed=21 + k,
                room=OPEN,
                robot_starts=tuple((*p, 0.0) for p in OPEN_STARTS),
            )
            row = run_one(sc, out_dir)
            ok += row["outcome"] == "arrest" and row["wall_replans"] == 0  # before any wall
        rows.append({"speed": v, "arrested": ok, "runs": 2})
    arrested = [r["speed"] for r in rows if r["arrested"] == r["runs"]]
    return {"speeds": rows, "edge_m_s": max(arrested) if arrested else None}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--no-edge", action="store_true")
    ap.add_argument("--speeds", default="0.30,0.35,0.40,0.45")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    out = tempfile.mkdtemp(prefix="arrest-bench-")
    rows = [run_one(sc, Path(out)) for sc in SCENARIOS if not args.only or sc.name in args.only]
    held = [r["hold_displacement_m"] for r in rows if r["outcome"] == "arrest"]
    result = {
        "bench": "arrest",
        "load_avg_1m": os.getloadavg()[0],
        "runs": rows,
        "as_expected": sum(r["as_expected"] for r in rows),
        "total": len(rows),
        "hold_displacement_m": {
            "n": len(held),
            "median": statistics.median(held) if held else None,
            "max": max(held) if held else None,
        },
    }
    if not args.no_edge:
        result["speed_edge"] = speed_edge([float(s) for s in args.speeds.split(",")], Path(out))
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
