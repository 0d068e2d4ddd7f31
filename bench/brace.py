"""What a look for braces costs (issue 34, item 10): prints ONE JSON object.

The speed edge's seeded cases (``bench/arrest.py``: a 0.8 x 0.5 m crate running a line at
``--speed`` m/s across the open room, six omni robots of 0.5 m/s) at their first sight: per
seed, the job's look for braces (``mission.brace.braced_capture``: the brace set, a mixed-integer
LP, its robots, the capture set planned again around them, the assignment) and, as the baseline
in this process, the capture plan the job makes at the start (``plan_capture_set``: the GA and
its reinforcement). Both run off the control tick, as jobs of kind ``capture`` on the planner
port. Reports the medians and the largest times (ms), the ratio of the medians, and on how many
seeds a brace set was found.

Usage: ``python bench/brace.py [--seeds 10] [--speed 0.45] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.arrest import edge_case, rules  # noqa: E402
from controller.mission.brace import braced_capture  # noqa: E402
from controller.mission.types import FleetView  # noqa: E402
from controller.planning.capture_set import plan_capture_set  # noqa: E402
from tests.support.arrest_scenarios import arrest_config  # noqa: E402


def first_sight(cfg, sc) -> FleetView:
    """What the job sees at the start: every robot at its start, the object at its start with
    its line's velocity."""
    n = len(cfg.robots)
    poses = np.array([list(p) for p in sc.robot_starts], float)
    h, v = sc.motion["heading"], sc.motion["speed"]
    vel = np.array([v * math.cos(h), v * math.sin(h), 0.0])
    return FleetView(
        0.0, cfg.robot_ids, poses, np.zeros((n, 3)), np.zeros(n, bool), np.ones(n, bool),
        np.asarray(sc.start, float), vel, None, False,
    )  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--speed", type=float, default=0.45)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    out: dict = {"bench": "brace", "load_average": [round(x, 2) for x in os.getloadavg()]}
    look, plan, braced = [], [], 0
    for k in range(args.seeds):
        sc, _ = edge_case(args.speed, k)
        cfg = arrest_config(rules(sc, "brace"))
        for r in range(args.repeats):
            t0 = time.perf_counter()
            capture = plan_capture_set(cfg, np.random.default_rng(cfg.capture.seed))
            plan.append(time.perf_counter() - t0)
            view = first_sight(cfg, sc)
            t0 = time.perf_counter()
            got = braced_capture(cfg, capture, view, np.ones(len(cfg.robots), bool))
            look.append(time.perf_counter() - t0)
            braced += int(r == 0 and got is not None)
    ms = {
        "brace_look_ms_median": round(1000 * statistics.median(look), 1),
        "brace_look_ms_max": round(1000 * max(look), 1),
        "capture_plan_ms_median": round(1000 * statistics.median(plan), 1),
        "capture_plan_ms_max": round(1000 * max(plan), 1),
    }
    out.update(ms)
    out["ratio_look_to_plan"] = round(ms["brace_look_ms_median"] / ms["capture_plan_ms_median"], 3)
    out["braced_seeds"] = braced
    out["seeds"] = args.seeds
    out["speed_m_s"] = args.speed
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
