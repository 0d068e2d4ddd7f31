"""Route-planner benchmark: prints ONE JSON object on stdout (progress on stderr).

- ``doorway``: the issue's case: a 1 m L-shaped crate carried by robots of radius 0.1 m through
  a 1.7 m doorway (it needs about 1.4 m) at the default 0.1 m; the route is checked move by move
  with shapely (straight moves exactly, turns sampled to 0.1 mm): its clearance beyond the
  robot ring must be >= 0.
- ``object``: the object's (x, y, theta) search on the shipped 12.8 m map (``yamashita``) at
  128^2, 256^2 and 512^2 cells x 36 headings, every goal, default ``[route]`` parameters (the
  ``cost_to_go`` heuristic). Each size runs in its own process (peak RSS is that process's):
  C-space build, the per-goal table (RoutePlanner), the first search (cold move cache), a
  re-plan from the start and from a pose off the route (warm), expansions.
- ``optimality`` (128^2): the default's cost against the optimum, from A* with the paper's
  admissible wavefront potential (an independent heuristic), and the old default ``skeleton``.
- ``two_d``: a robot-disc grid search (:class:`RobotRoadmap`, its default heuristic: octile
  distance tightened by landmarks, w_g = w_h = 1) on seeded 128^2 and 256^2 mazes and the
  shipped room, against PyPI ``pathfinding``'s A* on the same occupancy with the same
  8-connected moves (``DiagonalMovement.always``, its octile heuristic): search against search,
  and each with its grid build (ours includes the landmarks). Both optimal: the costs are
  checked equal. Also ours with the octile distance alone (the same heuristic as
  ``pathfinding``: the loop's speed alone) and with the exact wavefront, for reference.

Medians of repeated runs, interleaved (wall clock); the machine is shared, so trust the ratios
more than the absolute figures (``load`` gives the 1-minute load average at start and end).
Usage: ``python bench/route.py [--repeats N] [--sizes 128,256,512]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.config import RouteSection, load_config  # noqa: E402
from controller.planning.cspace import (  # noqa: E402
    GridFrame,
    RobotCSpace,
    build_object_cspace,
    build_robot_cspace,
)
from controller.planning.roadmap import RobotRoadmap  # noqa: E402
from controller.planning.route import RoutePlanner, plan_route  # noqa: E402
from controller.planning.route_maps import load_route_map  # noqa: E402
from tests.support.route_check import route_clearance  # noqa: E402

CRATE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]])


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


# --------------------------------------------------------------------------- the doorway


def bench_doorway() -> dict:
    room = np.array([[0.0, 0.0], [7.0, 5.0]])
    obstacles = [rect(3.4, 0.0, 3.6, 1.6), rect(3.4, 3.3, 3.6, 5.0)]  # a 1.7 m doorway
    start, goal = (0.8, 2.0, 0.0), (5.4, 2.0, 0.0)
    out = {"room_m": [7.0, 5.0], "doorway_m": 1.7, "crate_m": 1.0, "robot_radius_m": 0.1}
    for res_m in (0.1, 0.05):
        t0 = time.perf_counter()
        r = plan_route(room, obstacles, CRATE, 0.1, start, goal, RouteSection(resolution=res_m))
        dt = time.perf_counter() - t0
        row = {"status": r.status, "seconds": dt, "expanded": r.expanded, "cost_s": r.cost}
        if r.ok:
            row["clearance_beyond_ring_m"] = route_clearance(r, CRATE, obstacles, room) - 0.2
            row["never_within_ring"] = row["clearance_beyond_ring_m"] >= -1e-9
        out[f"{res_m:g} m"] = row
        log(f"doorway at {res_m} m: {r.status}, {dt:.2f} s, {r.expanded} expanded")
    return out


# --------------------------------------------------------------------------- the object search


def one_size(n: int, repeats: int) -> dict:
    """The object search at n x n x 36 on the shipped map (run in its own process)."""
    m = load_route_map("yamashita")
    res_m = float(m.bounds[1, 0] - m.bounds[0, 0]) / n
    params = RouteSection(resolution=res_m)
    t0 = time.perf_counter()
    cs = build_object_cspace(
        m.bounds, list(m.obstacles), m.footprint, m.robot_radius, res_m, params.heading_bins
    )
    out: dict = {
        "grid": [cs.frame.nx, cs.frame.ny, cs.heading_bins],
        "states": cs.counts["states"],
        "resolution_m": res_m,
        "cspace_seconds": time.perf_counter() - t0,
        "cspace_exact_checked": cs.counts["exact_checked"],
        "goals": {},
    }
    for name, goal in m.goals:
        t0 = time.perf_counter()
        planner = RoutePlanner(cs, goal, params)
        t_table = time.perf_counter() - t0
        t0 = time.perf_counter()
        r = planner.plan(m.start)
        t_first = time.perf_counter() - t0
        assert r.ok, r.reason
        again = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            planner.plan(m.start)
            again.append(time.perf_counter() - t0)
        off = r.waypoints[len(r.waypoints) // 3] + np.array([0.04, -0.03, 0.05])
        t0 = time.perf_counter()
        r_off = planner.plan(off) if cs.is_free(off) else None
        t_off = time.perf_counter() - t0
        out["goals"][name] = {
            "table_seconds": t_table,
            "search_seconds": t_first,
            "replan_seconds": statistics.median(again),
            "replan_off_route_seconds": t_off if r_off is not None else None,
            "replan_off_route_expanded": r_off.expanded if r_off is not None else None,
            "expanded": r.expanded,
            "reexpanded": r.reexpanded,
            "cost_s": r.cost,
            "length_m": r.length_m,
            "manipulations": r.manipulations,
        }
        log(
            f"{n}^2 {name}: table {t_table:.2f} s, search {t_first:.3f} s ({r.expanded} expanded),"
            f" re-plan {statistics.median(again):.3f} s"
        )
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    g = out["goals"]
    out["median_search_seconds"] = statistics.median(v["search_seconds"] for v in g.values())
    out["max_search_seconds"] = max(v["search_seconds"] for v in g.values())
    out["max_total_seconds"] = out["cspace_seconds"] + max(
        v["table_seconds"] + v["search_seconds"] for v in g.values()
    )
    return out


def bench_object(sizes: list[int], repeats: int) -> dict:
    out = {}
    for n in sizes:
        cmd = [sys.executable, __file__, "--one", str(n), "--repeats", str(repeats)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        sys.stderr.write(proc.stderr)
        if proc.returncode != 0:
            out[str(n)] = {"error": proc.stderr.strip().splitlines()[-1:]}
            continue
        out[str(n)] = json.loads(proc.stdout)
    return out


def bench_optimality() -> dict:
    """At 128^2: the default's cost against the optimum (A* with the admissible wavefront)."""
    m = load_route_map("yamashita")
    base = RouteSection()
    cs = build_object_cspace(
        m.bounds, list(m.obstacles), m.footprint, m.robot_radius, base.resolution, 36
    )
    out = {}
    for name, goal in m.goals:
        row = {}
        for kind in ("cost_to_go", "wavefront", "skeleton"):
            p = dataclasses.replace(base, heuristic=kind)
            t0 = time.perf_counter()
            r = RoutePlanner(cs, goal, p).plan(m.start)
            row[kind] = {
                "cost_s": r.cost,
                "expanded": r.expanded,
                "seconds": time.perf_counter() - t0,
            }
        opt = row["wavefront"]["cost_s"]
        row["optimum_s"] = opt
        row["default_gap_pct"] = 100.0 * (row["cost_to_go"]["cost_s"] / opt - 1.0)
        row["skeleton_gap_pct"] = 100.0 * (row["skeleton"]["cost_s"] / opt - 1.0)
        out[name] = row
        log(
            f"optimality {name}: default gap {row['default_gap_pct']:.3f} %, skeleton "
            f"{row['skeleton_gap_pct']:.1f} %"
        )
    return out


# --------------------------------------------------------------------------- 2-D robot A*


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
        y0 = 1 + min(i, a) * pitch
        x0 = 1 + min(j, b) * pitch
        if a != i:
            occ[y0 : y0 + pitch + corridor, x0 : x0 + corridor] = False
        else:
            occ[y0 : y0 + corridor, x0 : x0 + pitch + corridor] = False
        stack.append((a, b))
    for _ in range(m * m // 8):
        i, j = (int(v) for v in rng.integers(0, m - 1, 2))
        y0, x0 = 1 + i * pitch, 1 + j * pitch
        occ[y0 : y0 + corridor, x0 + corridor] = False
    return occ


def _corner_cells(occ: np.ndarray) -> tuple[tuple[int, int], tuple[int, int]]:
    free = np.argwhere(~occ)
    start = tuple(int(v) for v in free[np.lexsort((free[:, 1], free[:, 0]))][0])
    goal = tuple(int(v) for v in free[np.lexsort((-free[:, 1], -free[:, 0]))][0])
    return start, goal


def bench_2d_case(name: str, occ: np.ndarray, repeats: int) -> dict:
    from pathfinding.core.diagonal_movement import DiagonalMovement
    from pathfinding.core.grid import Grid
    from pathfinding.finder.a_star import AStarFinder

    ny, nx = occ.shape
    frame = GridFrame(0.0, 0.0, 1.0, nx, ny)
    start, goal = _corner_cells(occ)
    sxy = (start[1] + 0.5, start[0] + 0.5)
    gxy = (goal[1] + 0.5, goal[0] + 0.5)
    matrix = (~occ).astype(int).tolist()
    times: dict[str, list[float]] = {k: [] for k in ("build", "search", "exact", "octile")}
    times["pf_build"] = []
    times["pf_search"] = []
    res = res_exact = res_octile = None
    path: list = []
    runs = 0
    for _ in range(repeats):  # interleaved, so load hits both alike
        t0 = time.perf_counter()
        roadmap = RobotRoadmap(RobotCSpace.from_occupancy(occ, frame))
        times["build"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        res = roadmap.plan(sxy, gxy)
        times["search"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        res_exact = roadmap.plan(sxy, gxy, heuristic="wavefront")
        times["exact"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        res_octile = roadmap.plan(sxy, gxy, heuristic="octile")
        times["octile"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        grid = Grid(matrix=matrix)
        times["pf_build"].append(time.perf_counter() - t0)
        finder = AStarFinder(diagonal_movement=DiagonalMovement.always)
        t0 = time.perf_counter()
        path, runs = finder.find_path(
            grid.node(start[1], start[0]), grid.node(goal[1], goal[0]), grid
        )
        times["pf_search"].append(time.perf_counter() - t0)
    assert res is not None and res.ok and res_exact is not None and res_octile is not None
    med = {k: statistics.median(v) for k, v in times.items()}
    pts = np.array([(p.x, p.y) for p in path], dtype=float)
    pf_cost = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    out = {
        "grid": [ny, nx],
        "free_cells": int((~occ).sum()),
        "ours_build_seconds": med["build"],
        "ours_search_seconds": med["search"],
        "ours_expanded": res.expanded,
        "ours_cost": res.cost,
        "ours_octile_only_search_seconds": med["octile"],
        "ours_octile_only_expanded": res_octile.expanded,
        "ours_exact_heuristic_search_seconds": med["exact"],
        "ours_exact_heuristic_expanded": res_exact.expanded,
        "pathfinding_build_seconds": med["pf_build"],
        "pathfinding_search_seconds": med["pf_search"],
        "pathfinding_expanded": int(runs),
        "pathfinding_cost": pf_cost,
        "same_cost": bool(math.isclose(res.cost, pf_cost, rel_tol=1e-9)),
        "speedup_search_vs_search": med["pf_search"] / med["search"],
        "speedup_with_builds": (med["pf_build"] + med["pf_search"])
        / (med["build"] + med["search"]),
        "speedup_octile_only_search_vs_search": med["pf_search"] / med["octile"],
        "speedup_exact_heuristic_search_vs_search": med["pf_search"] / med["exact"],
    }
    log(
        f"2-D {name}: ours {med['search'] * 1e3:.1f} ms ({res.expanded} expanded), pathfinding "
        f"{med['pf_search'] * 1e3:.1f} ms ({runs}); x{out['speedup_search_vs_search']:.2f} search,"
        f" x{out['speedup_with_builds']:.2f} with builds"
    )
    return out


def bench_2d(repeats: int) -> dict:
    rng = np.random.default_rng(20261122)
    out = {f"maze_{n}": bench_2d_case(f"maze {n}^2", maze(n, rng), repeats) for n in (128, 256)}
    cfg = load_config(Path(__file__).resolve().parent.parent / "fleet.toml")
    cs = build_robot_cspace(cfg.bounds_array(), cfg.obstacle_polygons(), 0.15, 0.05)
    out["room_256"] = bench_2d_case("fleet.toml room 256^2", cs.occupied, repeats)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sizes", default="128,256,512")
    ap.add_argument("--one", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one_size(args.one, args.repeats)))
        return
    load0 = os.getloadavg()[0]
    result = {
        "bench": "route",
        "repeats": args.repeats,
        "doorway": bench_doorway(),
        "object": bench_object([int(s) for s in args.sizes.split(",")], args.repeats),
        "optimality_128": bench_optimality(),
        "two_d": bench_2d(args.repeats),
    }
    result["load"] = [load0, os.getloadavg()[0]]
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
