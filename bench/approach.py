"""Approach benchmark: prints ONE JSON object on stdout (progress on stderr).

For 4, 20 and 50 robots in the 12.8 m room of fleet.toml (its obstacles, the L-shaped object
in the middle): the projective planner's step (envelope goals + Table I + robot-robot rotation,
all robots) and the safety filter (the osqp barrier QP), each tick on the robots' new positions
(robots move with the filtered velocities, so the warm start sees realistic changes).
Baseline in the same run: the same filter rebuilt from scratch every call (osqp setup, no warm
start). Medians and p90 over the ticks, in milliseconds.

Usage: ``python bench/approach.py [--ticks N]``.
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
from controller.approach import ApproachParams, capture_goals, plan_step  # noqa: E402
from controller.config import load_config  # noqa: E402
from controller.safety import SafetyFilter, SafetyParams  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def scatter(n: int, rng: np.random.Generator, obstacles, obj, bounds) -> np.ndarray:
    """n robot positions in free space, at least 0.35 m apart."""
    out: list[np.ndarray] = []
    while len(out) < n:
        p = rng.uniform(bounds[0] + 0.4, bounds[1] - 0.4)
        if any(geometry.polygon_signed_distance(p[None], o)[0] < 0.3 for o in [*obstacles, obj]):
            continue
        if out and np.min(np.linalg.norm(np.array(out) - p, axis=1)) < 0.35:
            continue
        out.append(p)
    return np.array(out)


def pct(a: list[float], q: float) -> float:
    return round(float(np.quantile(a, q)) * 1e3, 4)


def run(n: int, ticks: int, cfg) -> dict:
    rng = np.random.default_rng(n)
    bounds = cfg.bounds_array()
    obstacles = cfg.obstacle_polygons()
    poly = cfg.object_polygon()
    obj_pose = np.array([6.0, 8.0, 0.3])
    obj_world = geometry.transform(poly, obj_pose)
    pos = scatter(n, rng, obstacles, obj_world, bounds)
    radii = np.full(n, 0.1)
    holo = np.arange(n) % 2 == 0
    speed = np.full(n, 0.4)
    params = ApproachParams.from_config(cfg.approach)
    sp = SafetyParams.from_config(cfg)
    sf = SafetyFilter(radii, holo, speed, bounds, obstacles, sp)
    # every robot gets a capture-like goal around the object (points on its boundary)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = geometry.centroid(poly)
    pts = c + 0.5 * np.stack([np.cos(ang), np.sin(ang)], 1)
    nrm = pts - c
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    heading = rng.uniform(-np.pi, np.pi, n)
    t_plan, t_filter, t_cold = [], [], []
    for k in range(ticks):
        t0 = time.perf_counter()
        env, _ = capture_goals(pts, nrm, radii, obj_pose, poly, params)
        res = plan_step(pos, radii, env, np.zeros((n, 2)), speed, heading, obstacles,
                        np.ones(n, bool), params, rng, avoid_object=np.ones(n, bool),
                        object_polygon=obj_world)  # fmt: skip
        t1 = time.perf_counter()
        fr = sf.filter(pos, res.velocity, object_polygon=obj_world, object_velocity=np.zeros(3))
        t2 = time.perf_counter()
        t_plan.append(t1 - t0)
        t_filter.append(t2 - t1)
        if k % 4 == 0:  # the cold baseline, on the same inputs
            cold = SafetyFilter(radii, holo, speed, bounds, obstacles, sp)
            t3 = time.perf_counter()
            cold.filter(pos, res.velocity, object_polygon=obj_world, object_velocity=np.zeros(3))
            t_cold.append(time.perf_counter() - t3)
        heading = res.heading
        pos = pos + 0.05 * fr.velocities
    out = {
        "robots": n,
        "ticks": ticks,
        "planner_ms": {"median": pct(t_plan, 0.5), "p90": pct(t_plan, 0.9)},
        "filter_ms": {"median": pct(t_filter, 0.5), "p90": pct(t_filter, 0.9)},
        "filter_cold_rebuild_ms": {"median": pct(t_cold, 0.5), "p90": pct(t_cold, 0.9)},
        "warm_speedup_vs_cold": round(float(np.median(t_cold) / np.median(t_filter)), 2),
        "infeasible": sf.infeasible,
        "relaxed": sf.relaxed,
    }
    log(f"{n} robots: planner {out['planner_ms']}, filter {out['filter_ms']}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ticks", type=int, default=200)
    args = ap.parse_args()
    cfg = load_config(ROOT / "fleet.toml")
    results = {str(n): run(n, args.ticks, cfg) for n in (4, 20, 50)}
    print(
        json.dumps(
            {
                "bench": "approach",
                "results": results,
                "goal_filter_ms_at_20": 2.0,
                "goal_met": results["20"]["filter_ms"]["median"] < 2.0,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
