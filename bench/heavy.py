"""Heavy loads benchmark (issue 34, item 9): prints ONE JSON object on stdout (progress on
stderr).

1. ``pushability``: per object, the time to learn every direction the fleet can push it
   (72 buckets of the transport's own set, ``wrench_set``) and the LP bound over every
   candidate contact; the best share of the floor friction each reaches.
2. ``route``: the route planner with and without keeping to the pushable ways, in the same
   process: first plan (s, the pushability table included), a re-plan from nearby, and the
   route's length, turning and re-arrangements.
3. ``closed_loop`` (``--runs``): the pybullet scenarios of the transport suite that need it
   (``turned-crate-pybullet``, ``heavy-trapezoid-pybullet``): status, transport time,
   re-arrangements, goal error, wall time.

Objects: the 0.8 x 0.5 m crate at 14.4 N of floor friction (six robots of 6 N: two fit on
the face that pushes it along the goal's direction), the issue's 12 kg trapezoid at mu 0.4
(eight robots of 15 N), and a crate at 29.4 N that no heading moves. Usage:
``python bench/heavy.py [--runs]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.mission.progress import route_planner_for  # noqa: E402
from controller.planning.route import RoutePlanner  # noqa: E402
from tests.support.transport_scenarios import SCENARIOS, TOO_HEAVY, scenario_config  # noqa: E402

CASES = {sc.name: sc for sc in SCENARIOS if sc.name in ("turned-crate-pybullet",
                                                         "heavy-trapezoid-pybullet")}  # fmt: skip
CASES[TOO_HEAVY.name] = TOO_HEAVY


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def route_figures(res) -> dict:
    return {
        "status": res.status,
        "too_heavy": res.too_heavy,
        "push_limited": res.push_limited,
        "length_m": round(res.length_m, 2),
        "rotation_deg": round(math.degrees(res.rotation_rad), 1),
        "manipulations": res.manipulations,
    }


def offline(name: str, sc) -> dict:
    cfg = scenario_config(sc)
    start = np.asarray(cfg.object.start, float)
    t = time.perf_counter()
    plain = RoutePlanner.from_config(cfg).plan(start)
    t_plain = time.perf_counter() - t
    planner = route_planner_for(cfg)
    t = time.perf_counter()
    pushed = planner.plan(start)
    t_first = time.perf_counter() - t
    t = time.perf_counter()
    planner.plan(start + np.array([0.05, 0.03, 0.02]))
    t_again = time.perf_counter() - t
    push = planner.push
    share, angle, robots, bound = push.best()
    return {
        "need_n": round(push.need, 1),
        "fleet_n": round(push.robots * push.weakest, 1),
        "pushability": {
            "buckets_learned": push.learned,
            "best_share": round(share, 3),
            "best_angle_deg": round(math.degrees(angle)),
            "best_robots": robots,
            "bound_share": round(bound, 3),
            "pushable_buckets": len(push.pushable_angles()),
        },
        "route": {
            "plain": route_figures(plain) | {"plan_s": round(t_plain, 3)},
            "pushed": route_figures(pushed)
            | {"first_plan_s": round(t_first, 3), "replan_s": round(t_again, 3)},
        },
    }


def closed_loop(name: str, sc) -> dict:
    from tests.scenarios.test_transport_scenarios import run

    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        res = run(sc, Path(d))
    fail = res.get("failure") or {}
    return {
        "status": res["status"],
        "reason": fail.get("reason"),
        "transport_time_s": res.get("transport_time_s"),
        "rearrangements": res.get("rearrangements"),
        "goal_error_m": None if res.get("goal_error_m") is None else round(res["goal_error_m"], 3),
        "goal_error_deg": None
        if res.get("goal_error_deg") is None
        else round(res["goal_error_deg"], 1),
        "wall_s": round(time.perf_counter() - t, 1),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", action="store_true", help="also the pybullet closed-loop runs")
    args = ap.parse_args()
    out: dict = {"bench": "heavy", "load_avg_start": round(os.getloadavg()[0], 2), "cases": {}}
    for name, sc in CASES.items():
        log(f"offline: {name}")
        out["cases"][name] = offline(name, sc)
        if args.runs and name != TOO_HEAVY.name:
            log(f"closed loop: {name}")
            out["cases"][name]["closed_loop"] = closed_loop(name, sc)
    out["load_avg_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
