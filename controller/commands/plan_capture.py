"""``fleet plan capture [--config F] [--json] [--plot F.png]``: the capture GA alone, offline.

Plans capture points for the config's object with the ``[capture]`` parameters, the fleet's
largest robot radius and at most as many robots as the fleet has. ``--json`` prints one object
for every outcome, with the fields: feasible (zero violated constraints and, with
``closure = "exact"``, the LP certificate), reason (why not, naming the constraint: too few
candidate nodes, robots too large for the object, spacing, closure impossible with the fleet,
the node budget of ``capture.spacing``; "" when feasible), violated (the constraints' names),
max_robots (the fleet size), candidates, normals, edges, chosen, points (empty when
infeasible), robots_needed, objective (-1e20 when infeasible), M_cw, M_ccw, N_cw, N_ccw,
paper_feasible, form_closure (LP certificate), closure, evaluations, seconds, history (best
objective per generation), note. Exit 0 with a feasible plan, 1 without one.
"""

from __future__ import annotations

import sys

from controller.commands import add_config_argument

EXAMPLES = """examples:
  fleet plan capture                          the capture points for ./fleet.toml's object
  fleet plan capture --config fleet.toml --json
  fleet plan capture --plot capture.png       and a figure of the plan
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, help="write a figure (PNG)")


def run(args) -> int:
    import time

    from controller.cli import emit_json
    from controller.config import load_config
    from controller.planning.capture import plan_for_fleet

    cfg = load_config(args.config)
    t0 = time.perf_counter()
    plan = plan_for_fleet(cfg)
    seconds = time.perf_counter() - t0
    if args.json:
        emit_json({**plan.to_json(), "seconds": seconds})
    else:
        print(f"{plan.text()}\n  ({seconds:.3f} s)")
    if not plan.feasible:
        print(f"fleet plan capture: infeasible: {plan.reason}", file=sys.stderr)
    if plan.note:
        print(f"fleet plan capture: note: {plan.note}", file=sys.stderr)
    if args.plot:
        from controller.viz import plot_capture_plan

        plot_capture_plan(args.plot, cfg.object_polygon(), plan)
    return 0 if plan.feasible else 1
