"""``fleet plan capture [--config F] [--json] [--plot F.png]``: the capture GA alone, offline.

Plans capture points for the config's object with the ``[capture]`` parameters and the
fleet's largest robot radius. ``--json`` fields: candidates, normals, edges, chosen, points,
robots_needed, objective, M_cw, M_ccw, N_cw, N_ccw, paper_feasible, form_closure (LP
certificate), evaluations, seconds, history (best objective per generation). Exit 1 when no
feasible capture is found or the fleet has fewer robots than the capture needs.
"""

from __future__ import annotations

import sys

from controller.commands import add_config_argument


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, help="write a figure (PNG)")


def run(args) -> int:
    import time

    import numpy as np

    from controller.cli import emit_json
    from controller.config import load_config
    from controller.planning.capture import CaptureParams, plan_capture

    cfg = load_config(args.config)
    params = CaptureParams.from_config(cfg.capture)
    t0 = time.perf_counter()
    try:
        plan = plan_capture(
            cfg.object_polygon(),
            cfg.max_robot_radius,
            params,
            np.random.default_rng(cfg.capture.seed),
        )
    except ValueError as exc:
        print(f"fleet plan capture: {exc}", file=sys.stderr)
        return 1
    seconds = time.perf_counter() - t0
    out = plan.to_json()
    out["seconds"] = seconds
    status = 0
    feasible = plan.form_closure if params.closure == "exact" else plan.paper_feasible
    if not feasible:
        print("fleet plan capture: no feasible capture found", file=sys.stderr)
        status = 1
    elif plan.robots_needed > len(cfg.robots):
        print(
            f"fleet plan capture: the capture needs {plan.robots_needed} robots; "
            f"the fleet has {len(cfg.robots)}",
            file=sys.stderr,
        )
        status = 1
    if plan.note:
        print(f"fleet plan capture: note: {plan.note}", file=sys.stderr)
    if args.json:
        emit_json(out)
    else:
        print(
            f"capture: {plan.robots_needed} robots, objective {plan.objective:.4g}, "
            f"N_cw {plan.N_cw} N_ccw {plan.N_ccw}, form closure {plan.form_closure}, "
            f"{plan.evaluations} evaluations in {seconds:.3f} s"
        )
        for p, n in zip(plan.points, plan.push_normals, strict=True):
            print(f"  point ({p[0]:.3f}, {p[1]:.3f}) normal ({n[0]:.2f}, {n[1]:.2f})")
    if args.plot:
        from controller.viz import plot_capture_plan

        plot_capture_plan(args.plot, cfg.object_polygon(), plan)
    return status
