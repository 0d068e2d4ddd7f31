"""Object-route speed (issue 23 item 7): the fast search against the reference, one process.

Prints ONE JSON object on stdout (progress on stderr). For each map and heuristic, ``old`` is
the code of before (``controller/planning/{cspace,heuristics,route}.py`` read from git at
``--old-commit`` and loaded beside today's, same process), ``ref_loop`` today's C-space with the
reference search loop (``plan(..., reference=True)``: the generic ``weighted_astar`` over
``_ObjectMoves``), and ``new`` today's default; each run builds its own C-space, so every side
starts with a cold move cache (moves checked exactly are cached on the C-space), then re-plans
once on the same planner (``warm``: the loop alone). All must give the same route and counts
(checked here too: ``same``). Reported: expansions, search seconds, microseconds per
expansion, the C-space build and the goal's table (``RoutePlanner``) seconds, the default
route's total (C-space + table + search), the ratios old / new, and PyPI ``pathfinding``'s A*
on the 2-D projection of the same problem (the cells free at some heading, 8-connected, start
cell to goal cell) as a peer for the cost per expansion of a Python A*.

Maps: ``maze`` a seeded 12.8 m maze (8 x 8 rooms of 1.6 m, 0.2 m walls) at 128^2 x 36, start
and goal in opposite corners; ``yamashita`` the shipped map at 128^2 x 36 (Goal4, the hard one);
``room_128`` / ``room_256`` the default ``fleet.toml`` room, its object from ``object.start`` to
``object.goal``, at 0.1 m and 0.05 m. Medians of ``--repeats`` (>= 3) interleaved runs; the
1-minute load average at start and end (the machine is shared: trust the ratios).
Usage: ``python bench/route_speed.py [--repeats 3] [--maps maze,yamashita,room_128,room_256]
[--heuristics cost_to_go,euclid,wavefront,skeleton]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.config import RouteSection, load_config  # noqa: E402
from controller.planning.cspace import build_object_cspace  # noqa: E402
from controller.planning.route import RoutePlanner  # noqa: E402
from controller.planning.route_maps import load_route_map  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
L_SHAPE = np.array(
    [[-0.4, -0.25], [0.4, -0.25], [0.4, 0.0], [-0.15, 0.0], [-0.15, 0.25], [-0.4, 0.25]]
)
# the paper's heuristics on the hard cases take long in the old loop: cap them so that a run of
# the whole bench stays within minutes (a capped run is reported with "limited": true)
MAX_EXPANDED = 50_000


OLD_COMMIT = "7f6c25c"  # the branch's base: the route code before issue 23 item 7


def old_code(commit: str) -> types.SimpleNamespace:
    """cspace, heuristics and route as they were at ``commit``, loaded as modules of their own
    (``old_planning_*``); everything else (config, geometry) is today's, unchanged since."""
    mods = {}
    for name in ("heuristics", "cspace", "route"):
        src = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{commit}:controller/planning/{name}.py"],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
        src = src.replace(
            "from controller.planning.cspace import", "from old_planning_cspace import"
        )
        src = src.replace(
            "from controller.planning import heuristics",
            "import old_planning_heuristics as heuristics",
        )
        mod = types.ModuleType(f"old_planning_{name}")
        sys.modules[mod.__name__] = mod
        exec(compile(src, f"{commit}:controller/planning/{name}.py", "exec"), mod.__dict__)
        mods[name] = mod
    return types.SimpleNamespace(**mods)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def object_maze(seed: int, rooms: int = 8, pitch: float = 1.6, wall: float = 0.2) -> list:
    """Wall rectangles of a seeded perfect maze (recursive backtracker) of rooms x rooms."""
    rng = np.random.default_rng(seed)
    seen = np.zeros((rooms, rooms), dtype=bool)
    open_e = np.zeros((rooms, rooms), dtype=bool)  # wall east of (i, j) removed
    open_n = np.zeros((rooms, rooms), dtype=bool)  # wall north of (i, j) removed
    stack = [(0, 0)]
    seen[0, 0] = True
    while stack:
        i, j = stack[-1]
        nbrs = [
            (i + di, j + dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < rooms and 0 <= j + dj < rooms and not seen[i + di, j + dj]
        ]
        if not nbrs:
            stack.pop()
            continue
        a, b = nbrs[int(rng.integers(len(nbrs)))]
        seen[a, b] = True
        if a != i:
            open_n[min(i, a), j] = True
        else:
            open_e[i, min(j, b)] = True
        stack.append((a, b))
    half = wall / 2
    out = []
    for i in range(rooms):  # i: row (y), j: column (x)
        for j in range(rooms):
            x1, y1 = (j + 1) * pitch, (i + 1) * pitch
            if j < rooms - 1 and not open_e[i, j]:
                out.append(rect(x1 - half, i * pitch, x1 + half, y1))
            if i < rooms - 1 and not open_n[i, j]:
                out.append(rect(j * pitch, y1 - half, x1, y1 + half))
    return out


def cases(names: list[str]) -> dict:
    """name -> (bounds, obstacles, footprint, robot radius, start, goal, resolution)."""
    out = {}
    if "maze" in names:
        c = 0.8  # the centre of the first room
        out["maze"] = (
            np.array([[0.0, 0.0], [12.8, 12.8]]),
            object_maze(20261126),
            L_SHAPE,
            0.1,
            np.array([c, c, 0.0]),
            np.array([12.8 - c, 12.8 - c, np.pi / 2]),
            0.1,
        )
    if "yamashita" in names:
        m = load_route_map("yamashita")
        goal = dict(m.goals)["Goal4"]
        out["yamashita"] = (m.bounds, list(m.obstacles), m.footprint, m.robot_radius,
                            m.start, goal, 0.1)  # fmt: skip
    cfg = load_config(ROOT / "fleet.toml")
    room = (
        cfg.bounds_array(),
        cfg.obstacle_polygons(),
        cfg.object_polygon(),
        cfg.max_robot_radius,
        np.asarray(cfg.object.start, dtype=float),
        np.asarray(cfg.object.goal, dtype=float),
    )
    for name, res in (("room_128", 0.1), ("room_256", 0.05)):
        if name in names:
            out[name] = (*room, res)
    return out


def one_run(case: tuple, kind: str, side: str, old) -> dict:
    bounds, obstacles, poly, radius, start, goal, res = case
    params = RouteSection(resolution=res, heading_bins=36, heuristic=kind)
    build, planner_cls = build_object_cspace, RoutePlanner
    kw = {"max_expanded": MAX_EXPANDED}
    if side == "old":
        build, planner_cls = old.cspace.build_object_cspace, old.route.RoutePlanner
    elif side == "ref_loop":
        kw["reference"] = True
    t0 = time.perf_counter()
    cs = build(bounds, obstacles, poly, radius, res, 36)
    t1 = time.perf_counter()
    planner = planner_cls(cs, goal, params)
    t2 = time.perf_counter()
    r = planner.plan(start, **kw)
    t3 = time.perf_counter()
    r2 = planner.plan(start, **kw)
    t4 = time.perf_counter()
    assert r2.expanded == r.expanded and r2.cost == r.cost
    return {
        "cspace": t1 - t0,
        "table": t2 - t1,
        "search": t3 - t2,
        "warm": t4 - t3,
        "result": r,
        "free2d": cs.free.any(axis=0),
        "cells": (cs.frame.cell_of(cs.ref_pose(start)[:2]), cs.frame.cell_of(cs.ref_pose(goal))),
    }


def pathfinding_2d(free2d: np.ndarray, cells, repeats: int) -> dict:
    """PyPI pathfinding's A* (8-connected, its octile heuristic) on the 2-D projection."""
    from pathfinding.core.diagonal_movement import DiagonalMovement
    from pathfinding.core.grid import Grid
    from pathfinding.finder.a_star import AStarFinder

    (sy, sx), (gy, gx) = cells
    matrix = free2d.astype(int).tolist()
    times, runs, path = [], 0, []
    for _ in range(repeats):
        grid = Grid(matrix=matrix)
        finder = AStarFinder(diagonal_movement=DiagonalMovement.always)
        t0 = time.perf_counter()
        path, runs = finder.find_path(grid.node(sx, sy), grid.node(gx, gy), grid)
        times.append(time.perf_counter() - t0)
    t = statistics.median(times)
    # pathfinding counts loop iterations ("runs"): one per node taken off its open list
    return {"search_seconds": t, "expanded": int(runs), "us_per_expansion": 1e6 * t / max(runs, 1),
            "path_cells": len(path)}  # fmt: skip


def bench_case(name: str, case: tuple, kinds: list[str], repeats: int, old) -> dict:
    out: dict = {}
    for kind in kinds:
        runs: dict[str, list[dict]] = {"old": [], "ref_loop": [], "new": []}
        for _ in range(repeats):  # interleaved, so load hits all alike
            for side, rs in runs.items():
                rs.append(one_run(case, kind, side, old))
        row: dict = {}
        for side, rs in runs.items():
            r = rs[0]["result"]
            med = {k: statistics.median(x[k] for x in rs) for k in ("cspace", "table", "search",
                                                                      "warm")}  # fmt: skip
            row[side] = {
                "status": r.status,
                "limited": "limit" in r.reason,
                "expanded": r.expanded,
                "generated": r.generated,
                "cost_s": r.cost if np.isfinite(r.cost) else None,
                "cspace_seconds": med["cspace"],
                "table_seconds": med["table"],
                "search_seconds": med["search"],
                "us_per_expansion": 1e6 * med["search"] / max(r.expanded, 1),
                "warm_search_seconds": med["warm"],
                "warm_us_per_expansion": 1e6 * med["warm"] / max(r.expanded, 1),
                "total_seconds": med["cspace"] + med["table"] + med["search"],
            }
        b = runs["new"][0]["result"]
        row["same"] = all(
            a.status == b.status
            and a.cost == b.cost
            and (a.expanded, a.generated, a.reexpanded) == (b.expanded, b.generated, b.reexpanded)
            and np.array_equal(a.waypoints, b.waypoints)
            for a in (runs["old"][0]["result"], runs["ref_loop"][0]["result"])
        )
        o, n = row["old"], row["new"]
        row["ratio"] = {
            k: o[k] / n[k] if n[k] > 0 else None
            for k in (
                "search_seconds",
                "warm_search_seconds",
                "cspace_seconds",
                "table_seconds",
                "total_seconds",
            )  # fmt: skip
        }
        out[kind] = row
        log(
            f"{name} {kind}: {n['expanded']} expanded, old {o['us_per_expansion']:.1f} µs/exp "
            f"(warm {o['warm_us_per_expansion']:.1f}), ref loop "
            f"{row['ref_loop']['us_per_expansion']:.1f} "
            f"(warm {row['ref_loop']['warm_us_per_expansion']:.1f}), "
            f"new {n['us_per_expansion']:.1f} "
            f"(warm {n['warm_us_per_expansion']:.1f}); search x{row['ratio']['search_seconds']:.2f}"
            f"; total old {o['total_seconds']:.3f} s, new {n['total_seconds']:.3f} s; same "
            f"{row['same']}"
        )
    first = runs["new"][0]
    if all(c is not None for c in first["cells"]):
        out["pathfinding_2d"] = pathfinding_2d(first["free2d"], first["cells"], repeats)
        pf = out["pathfinding_2d"]
        log(f"{name} pathfinding 2-D: {pf['expanded']} expanded, {pf['us_per_expansion']:.1f} µs")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--maps", default="maze,yamashita,room_128,room_256")
    ap.add_argument("--heuristics", default="cost_to_go,euclid,wavefront,skeleton")
    ap.add_argument("--old-commit", default=OLD_COMMIT)
    args = ap.parse_args()
    old = old_code(args.old_commit)
    load0 = os.getloadavg()[0]
    kinds = args.heuristics.split(",")
    result: dict = {"bench": "route_speed", "repeats": args.repeats, "heading_bins": 36,
                    "max_expanded": MAX_EXPANDED, "old_commit": args.old_commit,
                    "maps": {}}  # fmt: skip
    for name, case in cases(args.maps.split(",")).items():
        res_kinds = kinds if name != "room_256" else ["cost_to_go"]
        result["maps"][name] = bench_case(name, case, res_kinds, args.repeats, old)
    result["load"] = [load0, os.getloadavg()[0]]
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
