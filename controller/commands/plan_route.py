"""``fleet plan route``: the object's global route (weighted A* with pathmax), offline.

``fleet plan route [--config F] [--map NAME|F --goal N] [--heuristic H] [--wg W] [--wh W]
[--json] [--plot F.png]``

Without ``--map`` the scenario is the config's world, obstacles, object start and goal, and the
fleet's largest robot radius. ``--map`` plans on a route map instead (a name shipped in
``controller/planning/maps/``, e.g. ``yamashita``, or a path) toward its goal ``--goal`` (number
or name). The search parameters come from the config's ``[route]`` section (defaults when
``--map`` is used without ``--config``); ``--heuristic``, ``--wg`` and ``--wh`` override them.
``--json`` fields: status, reason, waypoints, subgoals, cost, length_m, manipulations, expanded,
reexpanded, seconds, heuristic, wg, wh.
Exit status: 0 a route, 1 no path, 2 bad input (naming the file or flag and the key).
"""

from __future__ import annotations

import sys

from controller.commands import DEFAULT_CONFIG
from controller.config import HEURISTICS

JSON_FIELDS = (
    "status",
    "reason",
    "waypoints",
    "subgoals",
    "cost",
    "length_m",
    "manipulations",
    "expanded",
    "reexpanded",
    "seconds",
    "heuristic",
    "wg",
    "wh",
)


EXAMPLES = """examples:
  fleet plan route                             the object's route in ./fleet.toml's room
  fleet plan route --map yamashita --goal 4    on a shipped map, toward its goal 4
  fleet plan route --heuristic euclid --wh 2 --json --plot route.png
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("--config", default=None, help=f"fleet config (default: {DEFAULT_CONFIG})")
    parser.add_argument("--map", default=None, help="a route map: shipped name or TOML path")
    parser.add_argument("--goal", default="4", help="goal of the --map (number or name)")
    parser.add_argument(
        "--heuristic",
        choices=HEURISTICS,
        default=None,
        help="the A* heuristic (default: the config's route.heuristic)",
    )
    parser.add_argument("--wg", type=float, choices=(0.0, 1.0), default=None, help="0 or 1")
    parser.add_argument("--wh", type=float, default=None, help="heuristic weight >= 0")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, help="write a figure (PNG)")


def run(args) -> int:
    import time

    from controller.cli import emit_json
    from controller.planning.route import plan_route
    from controller.planning.route_maps import route_scenario

    over = {k: getattr(args, k) for k in ("heuristic", "wg", "wh") if getattr(args, k) is not None}
    config = args.config if (args.config or args.map) else DEFAULT_CONFIG
    sc = route_scenario(config, args.map, args.goal, over)
    p = sc.params
    print(
        f"fleet plan route: {p.heuristic}, wg={p.wg}, wh={p.wh}, "
        f"{p.resolution} m x {p.heading_bins} headings",
        file=sys.stderr,
    )
    t0 = time.perf_counter()
    res = plan_route(sc.bounds, sc.obstacles, sc.footprint, sc.robot_radius, sc.start, sc.goal, p)
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

        plot_route(args.plot, sc.bounds, sc.obstacles, sc.footprint, sc.start, sc.goal, res)
    return 0 if res.ok else 1
