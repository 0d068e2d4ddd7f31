"""``fleet plan route``: the object's global route (weighted A* with pathmax), offline.

``fleet plan route [--config F] [--map NAME|F --goal N] [--heuristic euclid|wavefront|skeleton]
[--wg W] [--wh W] [--json] [--plot F.png]``

Without ``--map`` the scenario is the config's world, obstacles, object start and goal, and the
fleet's largest robot radius. ``--map`` plans on a route map instead (a name shipped in
``controller/planning/maps/``, e.g. ``yamashita``, or a path) toward its goal ``--goal`` (number
or name).
The search parameters come from the config's ``[route]`` section (defaults when ``--map`` is used
without ``--config``); ``--heuristic``, ``--wg`` and ``--wh`` override them.
Exit status: 0 a route, 1 no path, 2 bad input.
"""

from __future__ import annotations

import sys
from typing import Any

from controller.commands import DEFAULT_CONFIG

HEURISTIC_CHOICES = ("euclid", "wavefront", "skeleton")
JSON_FIELDS = (
    "status",
    "waypoints",
    "subgoals",
    "cost",
    "length_m",
    "expanded",
    "seconds",
    "heuristic",
    "wg",
    "wh",
)


def add_arguments(parser, word: str) -> None:
    parser.add_argument("--config", default=None, help=f"fleet config (default: {DEFAULT_CONFIG})")
    parser.add_argument("--map", default=None, help="a route map: shipped name or TOML path")
    parser.add_argument("--goal", default="4", help="goal of the --map (number or name)")
    parser.add_argument("--heuristic", choices=HEURISTIC_CHOICES, default=None)
    parser.add_argument("--wg", type=float, choices=(0.0, 1.0), default=None, help="0 or 1")
    parser.add_argument("--wh", type=float, default=None, help="heuristic weight >= 0")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, help="write a figure (PNG)")


def run(args) -> int:
    import dataclasses
    import time

    from controller.cli import emit_json
    from controller.config import RouteSection, load_config
    from controller.planning.route import plan_route
    from controller.planning.route_maps import load_route_map

    params = RouteSection()
    if args.config is not None or args.map is None:
        cfg = load_config(args.config or DEFAULT_CONFIG)
        params = cfg.route
    if args.wh is not None and not args.wh >= 0:
        print(f"fleet plan route: --wh: expected >= 0, got {args.wh}", file=sys.stderr)
        return 2
    over: dict[str, Any] = {}
    if args.heuristic is not None:
        over["heuristic"] = args.heuristic
    if args.wg is not None:
        over["wg"] = args.wg
    if args.wh is not None:
        over["wh"] = args.wh
    params = dataclasses.replace(params, **over)
    if args.map is not None:
        try:
            rmap = load_route_map(args.map)
            goal = rmap.goal(args.goal)
        except (ValueError, KeyError) as exc:
            print(f"fleet plan route: {exc}", file=sys.stderr)
            return 2
        bounds, obstacles = rmap.bounds, list(rmap.obstacles)
        footprint, radius, start = rmap.footprint, rmap.robot_radius, rmap.start
    else:
        bounds, obstacles = cfg.bounds_array(), cfg.obstacle_polygons()
        footprint, radius = cfg.object_polygon(), cfg.max_robot_radius
        start, goal = cfg.object.start, cfg.object.goal
    print(
        f"fleet plan route: {params.heuristic}, wg={params.wg}, wh={params.wh}, "
        f"{params.resolution} m x {params.heading_bins} headings",
        file=sys.stderr,
    )
    t0 = time.perf_counter()
    res = plan_route(bounds, obstacles, footprint, radius, start, goal, params)
    seconds = time.perf_counter() - t0
    out = res.to_dict()
    out["seconds"] = seconds
    if args.json:
        emit_json({k: out[k] for k in JSON_FIELDS})
    elif res.ok:
        print(
            f"route: cost {res.cost:.1f} s, {res.length_m:.2f} m, {len(res.subgoals)} subgoals, "
            f"{res.manipulations} re-arrangements, N_open {res.expanded}, {seconds:.2f} s"
        )
    if not res.ok:
        print(f"fleet plan route: no path: {res.reason}", file=sys.stderr)
    if args.plot:
        from controller.viz import plot_route

        plot_route(args.plot, bounds, obstacles, footprint, start, goal, res)
    return 0 if res.ok else 1
