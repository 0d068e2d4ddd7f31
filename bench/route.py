"""Route-planner benchmark: prints ONE JSON object on stdout (progress on stderr).

- 2-D: a robot-disc grid search (:class:`controller.route.RobotRoadmap`, Euclid heuristic,
  w_g = w_h = 1) on seeded 128^2 and 256^2 mazes, against PyPI ``pathfinding``'s A* on the same
  occupancy with the same 8-connected moves (``DiagonalMovement.always``, its default octile
  heuristic), in the same run. Both optimal: the costs are checked equal.
- 3-D: the object's (x, y, theta) search on the shipped 12.8 m map at 0.1 m x 36 headings
  (128^2 x 36 cells), every goal, with the default [route] parameters (skeleton, w_g = w_h = 1);
  the C-space build and heuristic table are timed apart.

Medians of repeated runs (wall clock); the machine is shared, so trust the ratios more than the
absolute figures. Usage: ``python bench/route.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.config import RouteSection  # noqa: E402
from controller.planning.cspace import GridFrame, RobotCSpace, build_object_cspace  # noqa: E402
from controller.planning.roadmap import RobotRoadmap  # noqa: E402
from controller.planning.route import plan_route  # noqa: E402
from controller.planning.route_maps import load_route_map  # noqa: E402


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def maze(n: int, rng: np.random.Generator, corridor: int = 3) -> np.ndarray:
    """Occupancy (n, n) of a seeded maze (recursive backtracker plus a few loops)."""
    pitch = corridor + 1
    m = (n - 1) // pitch
    occ = np.ones((n, n), dtype=bool)
    seen = np.zeros((m, m), dtype=bool)
    stack = [(0, 0)]
    seen[0, 0] = True

    def room(i: int, j: int) -> None:
        occ[1 + i * pitch : 1 + i * pitch + corridor, 1 + j * pitch : 1 + j * pitch + corridor] = (
            False
        )

    room(0, 0)
    while stack:
        i, j = stack[-1]
        nbrs = [
            (i + di, j + dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < m and 0 <= j + dj < m and not seen[i + di, j + dj]
        ]
        if not nbrs:
            stack.pop()
            continue
        a, b = nbrs[int(rng.integers(len(nbrs)))]
        seen[a, b] = True
        room(a, b)
        # knock down the wall between (i, j) and (a, b)
        y0 = 1 + min(i, a) * pitch
        x0 = 1 + min(j, b) * pitch
        if a != i:
            occ[y0 : y0 + pitch + corridor, x0 : x0 + corridor] = False
        else:
            occ[y0 : y0 + corridor, x0 : x0 + pitch + corridor] = False
        stack.append((a, b))
    # a few extra openings so the maze has loops (more than one way)
    for _ in range(m * m // 8):
        i, j = (int(v) for v in rng.integers(0, m - 1, 2))
        y0, x0 = 1 + i * pitch, 1 + j * pitch
        occ[y0 : y0 + corridor, x0 + corridor] = False
    return occ


def median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def bench_2d(n: int, repeats: int, rng: np.random.Generator) -> dict:
    from pathfinding.core.diagonal_movement import DiagonalMovement
    from pathfinding.core.grid import Grid
    from pathfinding.finder.a_star import AStarFinder

    occ = maze(n, rng)
    frame = GridFrame(0.0, 0.0, 1.0, n, n)
    free = np.argwhere(~occ)
    start = tuple(free[np.lexsort((free[:, 1], free[:, 0]))][0])  # (iy, ix) near (0, 0)
    goal = tuple(free[np.lexsort((-free[:, 1], -free[:, 0]))][0])  # near (n, n)
    sxy = (start[1] + 0.5, start[0] + 0.5)
    gxy = (goal[1] + 0.5, goal[0] + 0.5)

    t_build, roadmap = median_time(
        lambda: RobotRoadmap(RobotCSpace.from_occupancy(occ, frame)), repeats
    )
    t_ours, res = median_time(lambda: roadmap.plan(sxy, gxy), repeats)
    assert res.ok, res.reason
    matrix = (~occ).astype(int).tolist()

    def run_pf():
        grid = Grid(matrix=matrix)
        finder = AStarFinder(diagonal_movement=DiagonalMovement.always)
        path, runs = finder.find_path(
            grid.node(start[1], start[0]), grid.node(goal[1], goal[0]), grid
        )
        return path, runs

    def run_pf_search_only():
        grid = Grid(matrix=matrix)
        finder = AStarFinder(diagonal_movement=DiagonalMovement.always)
        t0 = time.perf_counter()
        finder.find_path(grid.node(start[1], start[0]), grid.node(goal[1], goal[0]), grid)
        return time.perf_counter() - t0

    t_pf, (path, runs) = median_time(run_pf, repeats)
    t_pf_search = statistics.median(run_pf_search_only() for _ in range(repeats))
    pts = np.array([(p.x, p.y) for p in path], dtype=float)
    pf_cost = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    log(
        f"2-D {n}^2: ours {t_ours * 1e3:.1f} ms ({res.expanded} expanded), pathfinding "
        f"{t_pf * 1e3:.1f} ms ({runs} runs), search only {t_pf_search * 1e3:.1f} ms"
    )
    return {
        "grid": [n, n],
        "free_cells": int((~occ).sum()),
        "ours_seconds": t_ours,
        "ours_build_seconds": t_build,
        "ours_N_open": res.expanded,
        "ours_cost": res.cost,
        "pathfinding_seconds": t_pf,
        "pathfinding_search_only_seconds": t_pf_search,
        "pathfinding_N_open": int(runs),
        "pathfinding_cost": pf_cost,
        "same_cost": bool(math.isclose(res.cost, pf_cost, rel_tol=1e-9)),
        "speedup": t_pf / t_ours,
        "speedup_search_only": t_pf_search / t_ours,
    }


def bench_3d(repeats: int) -> dict:
    m = load_route_map("yamashita")
    params = RouteSection()
    t_build, cs = median_time(
        lambda: build_object_cspace(
            m.bounds,
            list(m.obstacles),
            m.footprint,
            m.robot_radius,
            params.resolution,
            params.heading_bins,
        ),
        repeats,
    )
    out = {
        "map": m.name,
        "grid": [cs.frame.nx, cs.frame.ny, cs.heading_bins],
        "heuristic": params.heuristic,
        "wg": params.wg,
        "wh": params.wh,
        "manipulation_cost": params.manipulation_cost,
        "cspace_build_seconds": t_build,
        "goals": {},
    }
    for name, goal in m.goals:
        c = cs.cell_of(goal)
        t_h, table = median_time(
            lambda c=c: object_heuristic(cs, params.heuristic, (c[1], c[2])), repeats
        )
        t_s, res = median_time(
            lambda g=goal, t=table: plan_route(
                None, None, None, None, m.start, g, params, cspace=cs, h_table=t
            ),
            repeats,
        )
        assert res.ok, res.reason
        log(f"3-D {name}: {t_s:.3f} s search, {res.expanded} expanded, cost {res.cost:.1f} s")
        out["goals"][name] = {
            "search_seconds": t_s,
            "heuristic_seconds": t_h,
            "N_open": res.expanded,
            "N_per_second": res.expanded / t_s,
            "cost_s": res.cost,
            "length_m": res.length_m,
            "manipulations": res.manipulations,
        }
    # the same four goals with the search's own admissible wavefront, for reference
    wf = dataclasses.replace(params, heuristic="wavefront")
    out["wavefront_N_open"] = {
        name: plan_route(None, None, None, None, m.start, g, wf, cspace=cs).expanded
        for name, g in m.goals
    }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(20261122)
    result = {
        "bench": "route",
        "repeats": args.repeats,
        "two_d": {str(n): bench_2d(n, args.repeats, rng) for n in (128, 256)},
        "three_d": bench_3d(max(1, args.repeats // 2)),
    }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
