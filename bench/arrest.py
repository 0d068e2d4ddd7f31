"""Arrest benchmark (JSON on stdout): the seeded arrest suite in pybullet with the object alive
through the hold (walls, corners, fast, evasive, concave), the hold displacement distribution
from ground truth, and the speed edge: the highest object speed arrested in open space by six
omni robots of 0.5 m/s.

    python bench/arrest.py [--only NAME ...] [--no-edge] [--no-suite] [--speeds 0.25,...]
                           [--seeds 10] [--variants baseline,new] [--quick] [--filter-off]

``--filter-off`` (Sharma et al.'s claim that the projective paths of the approach need no
safety filter): the suite twice in this process, on the same scenarios, with the safety filter
on and then off (every robot's velocity as the mission asks, only the tracking law's limits;
the filter is bypassed in this bench process alone, no config can turn it off); per run the
outcome, the robots' closest approach to each other and to the object from the world's truth,
and collisions (robots touching).

The speed edge runs every seed of every speed once per variant, in this process: ``baseline``
(the approach's rules before the interception of oncoming objects) and ``new``; each speed's
arrest rate comes with its Wilson 95 % interval, and ``paired`` counts the seeds only one
variant arrested. ``--quick`` is a profile (2 seeds at 0.40 and 0.45 m/s).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import stats  # noqa: E402
from controller.mission.factory import build_mission  # noqa: E402
from controller.planning import safety  # noqa: E402
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


@contextmanager
def filter_off() -> Iterator[None]:
    """The safety filter bypassed in this process: every robot gets its nominal velocity (a
    stale or held one zero), as the mission's planner asks it."""
    real = safety.SafetyFilter.filter

    def nominal(self, positions, u_nom, polygons, stale=None, **_kw):
        u = np.array(u_nom, float)
        if stale is not None:
            u[np.asarray(stale, bool)] = 0.0
        return safety.FilterResult(u, "off", np.zeros(self.n, bool), 0.0, None)

    safety.SafetyFilter.filter = nominal
    try:
        yield
    finally:
        safety.SafetyFilter.filter = real


def filter_pairs(wanted: list[ArrestScenario], out_dir: Path) -> dict:
    """Each scenario with the filter on, then off; collisions and closest approaches."""
    for sub in ("on", "off"):
        (out_dir / sub).mkdir(parents=True, exist_ok=True)
    on = [run_one(sc, out_dir / "on") for sc in wanted]
    with filter_off():
        off = [run_one(sc, out_dir / "off") for sc in wanted]

    def brief(r: dict) -> dict:
        gap = r["min_clearance_m"]
        reason = (r.get("failure") or {}).get("reason")
        return {
            "outcome": r["outcome"],
            "min_clearance_m": gap,
            "object_min_clearance_m": r["object_min_clearance_m"],
            "collision": bool(reason == "collision" or (gap is not None and gap < 0.0)),
        }

    runs = [
        {"name": sc.name, "on": brief(a), "off": brief(b)}
        for sc, a, b in zip(wanted, on, off, strict=True)
    ]
    return {
        "runs": runs,
        "collisions_on": sum(r["on"]["collision"] for r in runs),
        "collisions_off": sum(r["off"]["collision"] for r in runs),
        "arrests_on": sum(r["on"]["outcome"] == "arrest" for r in runs),
        "arrests_off": sum(r["off"]["outcome"] == "arrest" for r in runs),
    }


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
        "object_min_clearance_m": res.get("object_min_clearance_m"),
        "phases": [p["phase"] for p in res.get("phases", [])],
        "wall_s": round(time.perf_counter() - t0, 2),
    }
    log(f"{sc.name}: {outcome} (expect {sc.expect}) {row['wall_s']} s wall")
    return row


EDGE_SPEEDS = "0.25,0.30,0.35,0.40,0.45,0.50"
EDGE_SEEDS = 10
WALL_CLEAR_M = 0.05  # m: an arrest counts only if the object never came this near a wall
HOLD_MARGIN_S = 12.0  # s of sim time after the object would reach a wall: hold, arrest, settle


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson's 95 % score interval of a rate of k successes in n runs (``bench/stats.py``)."""
    lo, hi = stats.wilson(k, n)
    return (round(lo, 3), round(hi, 3))


def edge_case(v: float, k: int) -> tuple[ArrestScenario, float]:
    """Seed ``k`` of the speed edge at ``v`` m/s: the object (a 0.8 x 0.5 m crate) runs a line
    east across the open room (24 x 16 m) among six omni robots of 0.5 m/s spread over it.
    Seeds 0 and 1 are the two runs measured before (heading 0.3 from (5, 5), -0.6 from
    (5, 11)); the others draw the heading in [0, 0.6] rad, north and south by turns, and
    start on the side the line turns away from (y = 8 - 6 sin(heading) ± 0.5 m).
    Also returns the sim time (s) at which the object, unhindered, would reach a wall."""
    if k < 2:
        heading, y = ((0.3, 5.0), (-0.6, 11.0))[k]
    else:
        g = np.random.default_rng(1000 + k)
        heading = float(g.uniform(0.0, 0.6)) * (1 if k % 2 == 0 else -1)  # north, south by turns
        # start on the side it turns away from, as seeds 0 and 1 do: a long way to the wall
        y = 8.0 - 6.0 * math.sin(heading) + float(g.uniform(-0.5, 0.5))
    start = np.array([5.0, y])
    direction = np.array([math.cos(heading), math.sin(heading)])
    (x0, y0), (x1, y1) = OPEN
    reach = 0.5  # m: the crate's half diagonal, about
    free = []
    for axis, lo, hi in ((0, x0, x1), (1, y0, y1)):
        if direction[axis] > 1e-9:
            free.append((hi - reach - start[axis]) / direction[axis])
        elif direction[axis] < -1e-9:
            free.append((lo + reach - start[axis]) / direction[axis])
    t_wall = min(free) / v
    sc = ArrestScenario(
        f"edge-{v:.2f}-{k}",
        RECT,
        (5.0, y, 0.0),
        {"kind": "line", "speed": v, "heading": heading},
        kinds="oooooo",
        max_speed=0.5,
        seed=21 + k,
        room=OPEN,
        robot_starts=tuple((*p, 0.0) for p in OPEN_STARTS),
        max_time=round(t_wall + HOLD_MARGIN_S, 1),
    )
    return sc, t_wall


def rules(sc: ArrestScenario, variant: str) -> ArrestScenario:
    """The scenario with the approach's rules of a variant: ``new`` (``approach.intercept =
    "oncoming"``) or ``baseline`` (``"classic"``, the default: an interception only of targets
    slower than the robot, the goal's velocity ridden on at any distance)."""
    rule = "oncoming" if variant == "new" else "classic"
    approach = {**sc.patch.get("approach", {}), "intercept": rule}
    if variant != "brace":  # the rules before braces (the default: approach.brace_share 0.6)
        approach["brace_share"] = 0.0
    patch = {**sc.patch, "approach": approach}
    return dataclasses.replace(sc, patch=patch)


def speed_edge(speeds: list[float], seeds: int, variants: list[str], out_dir: Path) -> dict:
    """Arrest rate per object speed in open space (6 omni robots at 0.5 m/s), ``seeds`` runs
    per speed, each variant on the same seeds: an arrest counts only if it came before the
    object reached a wall (no wall re-plan, the object never within ``WALL_CLEAR_M`` of a wall
    by ground truth, and the run stops at the time the object would take to get there plus
    the hold)."""
    out: dict = {"seeds": seeds, "variants": {}}
    for variant in variants:
        rows, per_seed = [], {}
        for v in speeds:
            ok = 0
            for k in range(seeds):
                sc, t_wall = edge_case(v, k)
                row = run_one(rules(sc, variant), out_dir)
                clear = row["object_min_clearance_m"]
                hit = (
                    row["outcome"] == "arrest"
                    and row["wall_replans"] == 0
                    and clear is not None
                    and clear > WALL_CLEAR_M
                )
                ok += hit
                per_seed[f"{v:.2f}/{k}"] = {
                    "arrest": bool(hit),
                    "outcome": row["outcome"],
                    "wall_replans": row["wall_replans"],
                    "t_s": row["arrest_time_s"],
                    "t_wall_s": round(t_wall, 1),
                    "object_min_clearance_m": None if clear is None else round(clear, 3),
                }
            lo, hi = wilson(ok, seeds)
            rows.append(
                {
                    "speed": v,
                    "arrested": ok,
                    "runs": seeds,
                    "rate": ok / seeds,
                    "wilson95": [lo, hi],
                }
            )
        full = [r["speed"] for r in rows if r["arrested"] == r["runs"]]
        most = [r["speed"] for r in rows if r["rate"] >= 0.8]
        out["variants"][variant] = {
            "speeds": rows,
            "edge_m_s": max(full) if full else None,  # every seed arrested
            "edge80_m_s": max(most) if most else None,  # at least 80 % of the seeds
            "runs": per_seed,
        }
    if len(variants) == 2:
        a, b = (out["variants"][x]["runs"] for x in variants)
        out["paired"] = {
            f"{variants[1]}_only": sum(b[k]["arrest"] and not a[k]["arrest"] for k in a),
            f"{variants[0]}_only": sum(a[k]["arrest"] and not b[k]["arrest"] for k in a),
            "both": sum(a[k]["arrest"] and b[k]["arrest"] for k in a),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--no-edge", action="store_true")
    ap.add_argument("--no-suite", action="store_true", help="the speed edge alone")
    ap.add_argument("--speeds", default=EDGE_SPEEDS)
    ap.add_argument("--seeds", type=int, default=EDGE_SEEDS, help="runs per speed")
    ap.add_argument(
        "--variants",
        default="baseline,new",
        help="approach rules, each on the same seeds in this process: baseline, new",
    )
    ap.add_argument(
        "--quick", action="store_true", help="a profile: 2 seeds at 0.40 and 0.45, no suite"
    )
    ap.add_argument(
        "--filter-off",
        action="store_true",
        help="the suite with the safety filter on, then off (Sharma's claim); nothing else",
    )
    args = ap.parse_args()
    if args.quick:
        args.seeds, args.speeds, args.no_suite = 2, "0.40,0.45", True
    variants = [x for x in args.variants.split(",") if x]
    if set(variants) - {"baseline", "new", "brace"}:
        ap.error(f"--variants: expected baseline, new and/or brace, got {args.variants!r}")
    logging.basicConfig(level=logging.ERROR)
    out = tempfile.mkdtemp(prefix="arrest-bench-")
    wanted = [sc for sc in SCENARIOS if not args.only or sc.name in args.only]
    if args.filter_off:
        res = {"bench": "arrest_filter", "load_avg_1m": os.getloadavg()[0]}
        res.update(filter_pairs(wanted, Path(out)))
        res["load_avg_1m_end"] = os.getloadavg()[0]
        print(json.dumps(res, indent=1))
        return
    rows = [] if args.no_suite else [run_one(sc, Path(out)) for sc in wanted]
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
        speeds = [float(s) for s in args.speeds.split(",")]
        result["speed_edge"] = speed_edge(speeds, args.seeds, variants, Path(out))
        result["load_avg_1m_end"] = os.getloadavg()[0]
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
