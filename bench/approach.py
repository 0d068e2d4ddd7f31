"""Approach benchmark: prints ONE JSON object on stdout (progress on stderr).

For 4, 20 and 50 robots on a seeded random layout around a moving object (with the shipped
obstacles), times, per control tick:

- the projective planner step (:func:`controller.approach.plan_velocities`, all robots);
- the CBF safety filter (:class:`controller.safety.SafetyFilter`), warm-started with the sparsity
  pattern built once (ours), against the same QP rebuilt cold on every call (``warm=False``: a
  fresh osqp setup each tick), in the same process; and warm with half the fleet differential
  (a second solve with their axis rows). The issue quotes Robotarium's cvxopt barrier
  certificate at about 5 ms (20 robots) and 50 ms (50 robots) on this kind of machine.

Robots move along the filtered velocities between ticks (so the warm start sees a realistic
drift). Medians and p90 in milliseconds; the machine is shared, trust ratios more than absolute
figures. Usage: ``python bench/approach.py [--ticks N]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller import geometry  # noqa: E402
from controller.planning.approach import PlannerParams, plan_velocities  # noqa: E402
from controller.planning.safety import SafetyFilter  # noqa: E402

BOUNDS = np.array([[0.0, 0.0], [12.8, 12.8]])
OBSTACLES = [
    np.array([[5.6, 5.0], [7.2, 5.0], [7.2, 5.8], [5.6, 5.8]]),
    np.array([[9.0, 2.5], [9.6, 2.5], [9.6, 3.1], [9.0, 3.1]]),
    np.array([[3.0, 11.4], [4.8, 11.4], [4.8, 12.8], [3.0, 12.8]]),
]
OBJECT = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]])


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def stats(ts: list[float]) -> dict[str, float]:
    a = np.asarray(ts) * 1e3
    return {
        "median_ms": round(float(np.median(a)), 4),
        "p90_ms": round(float(np.percentile(a, 90)), 4),
    }


def layout(n: int, rng: np.random.Generator) -> np.ndarray:
    """n robot centres in free space, at least 0.35 m apart (rejection sampling)."""
    pts: list[np.ndarray] = []
    polys = OBSTACLES + [geometry.transform(OBJECT, [2.0, 3.0, 0.0])]
    while len(pts) < n:
        p = rng.uniform(0.5, 12.3, 2)
        if any(geometry.polygon_signed_distance(p[None], q)[0] < 0.3 for q in polys):
            continue
        if pts and np.min(np.linalg.norm(np.array(pts) - p, axis=1)) < 0.35:
            continue
        pts.append(p)
    return np.array(pts)


def bench(n: int, ticks: int, rng: np.random.Generator) -> dict:
    radii = np.full(n, 0.1)
    vmax = np.full(n, 0.4)
    params = PlannerParams(np.deg2rad(15), 2.5, np.deg2rad(15), 1.25, np.pi)
    p = layout(n, rng)
    heads = np.tile([1.0, 0.0], (n, 1))
    goals = layout(n, rng)
    warm = SafetyFilter(radii, vmax, BOUNDS, len(OBSTACLES) + 1, margin=0.05)
    cold = SafetyFilter(radii, vmax, BOUNDS, len(OBSTACLES) + 1, margin=0.05, warm=False)
    # half the fleet differential: the second solve, with their axis rows
    mixed = SafetyFilter(radii, vmax, BOUNDS, len(OBSTACLES) + 1, margin=0.05,
                         axial=np.arange(n) % 2 == 1)  # fmt: skip
    t_plan, t_warm, t_cold, t_mixed, changed = [], [], [], [], []
    obj = np.array([2.0, 3.0, 0.0])
    for _ in range(ticks):
        obj = obj + np.array([0.005, 0.0, 0.0])
        polys = OBSTACLES + [geometry.transform(OBJECT, obj)]
        t0 = time.perf_counter()
        vel, heads, _ = plan_velocities(
            p, heads, radii, vmax, goals, np.zeros((n, 2)), polys,
            np.ones((n, len(polys)), bool), np.ones(n, bool), params, rng,
        )  # fmt: skip
        t1 = time.perf_counter()
        res = warm.filter(p, vel, polys)
        t2 = time.perf_counter()
        ref = cold.filter(p, vel, polys)
        t3 = time.perf_counter()
        mixed.filter(p, vel, polys, headings=np.arctan2(heads[:, 1], heads[:, 0]))
        t_mixed.append(time.perf_counter() - t3)
        t_plan.append(t1 - t0)
        t_warm.append(t2 - t1)
        t_cold.append(t3 - t2)
        changed.append(float(np.abs(res.velocities - ref.velocities).max()))
        p = p + 0.05 * res.velocities
    sw, sc = stats(t_warm), stats(t_cold)
    return {
        "robots": n,
        "ticks": ticks,
        "constraints": warm.m,
        "planner": stats(t_plan),
        "filter_warm": sw,
        "filter_cold_rebuild": sc,
        "filter_warm_half_differential": stats(t_mixed),
        "speedup_median": round(sc["median_ms"] / max(sw["median_ms"], 1e-9), 2),
        "max_warm_vs_cold_diff_mps": round(max(changed), 5),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ticks", type=int, default=200)
    args = ap.parse_args()
    rng = np.random.default_rng(20261123)
    out = {"bench": "approach", "sizes": {}}
    for n in (4, 20, 50):
        log(f"{n} robots ...")
        out["sizes"][str(n)] = bench(n, args.ticks, rng)
    out["goal"] = "filter < 2 ms median at 20 robots"
    out["goal_met"] = out["sizes"]["20"]["filter_warm"]["median_ms"] < 2.0
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
