"""The paper's Tables 2 and 3 (Yamashita et al. §5.2-5.3) on the shipped 12.8 m map.

Table 2: N_open for heuristics (A) Euclid, (B) wavefront, (C) skeleton wavefront x Goals 1-4 with
w_g = w_h = 1, normalized to (A)/Goal1. Table 3: Goal 4 with the skeleton heuristic for
(w_g, w_h) = (1, 0), (1, 1), (0, 1), (1, 0.5): N_open and f (the route's cost, the value f takes
at the goal) normalized to Dijkstra (1, 0); the same with the admissible wavefront for reference.
Both tables twice: with the planner's default heuristic (potential + rotation bound +
manipulation bound) and with the paper's potentials alone (``turn_bound=False``).

Prints ONE JSON object on stdout (the raw figures, the ratios, and the Markdown tables as a
string); the Markdown goes to stderr as well, or alone to stdout with ``--markdown``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.config import RouteSection  # noqa: E402
from controller.planning.cspace import build_object_cspace  # noqa: E402
from controller.planning.route import object_heuristic, plan_route  # noqa: E402
from controller.planning.route_maps import load_route_map  # noqa: E402

PAPER_T2 = {
    "euclid": [1.00, 1.36, 2.96, 4.09],
    "wavefront": [0.90, 1.53, 2.32, 3.21],
    "skeleton": [0.83, 1.37, 2.16, 3.06],
}
PAPER_T3 = {(1.0, 0.0): (1.00, 1.00), (1.0, 1.0): (0.45, 1.00), (0.0, 1.0): (0.05, 2.50)}
PAPER_T3[(1.0, 0.5)] = (0.27, 1.00)
LABEL = {"euclid": "(A) Euclid", "wavefront": "(B) Wavefront", "skeleton": "(C) Skeleton"}
STRATEGIES = ((1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.5))


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--map", default="yamashita")
    ap.add_argument("--markdown", action="store_true", help="print only the Markdown tables")
    args = ap.parse_args()
    m = load_route_map(args.map)
    base = RouteSection()
    cs = build_object_cspace(
        m.bounds,
        list(m.obstacles),
        m.footprint,
        m.robot_radius,
        base.resolution,
        base.heading_bins,
    )
    goals = [n for n, _ in m.goals]
    tables: dict[tuple[str, str], object] = {}

    def table(kind: str, goal: str):
        if (kind, goal) not in tables:
            c = cs.cell_of(m.goal(goal))
            tables[(kind, goal)] = object_heuristic(cs, kind, (c[1], c[2]))
        return tables[(kind, goal)]

    def run(kind: str, goal: str, wg: float, wh: float, bound: bool) -> dict:
        p = dataclasses.replace(base, heuristic=kind, wg=wg, wh=wh)
        t0 = time.perf_counter()
        r = plan_route(
            None, None, None, None, m.start, m.goal(goal), p, cspace=cs,
            h_table=table(kind, goal), turn_bound=bound,
        )  # fmt: skip
        dt = time.perf_counter() - t0
        assert r.ok, r.reason
        log(
            f"{'bound' if bound else 'bare':5s} {kind:9s} {goal} wg={wg} wh={wh}: "
            f"N_open {r.expanded}, cost {r.cost:.2f} s, {dt:.2f} s"
        )
        return {
            "N_open": r.expanded,
            "cost_s": r.cost,
            "length_m": r.length_m,
            "manipulations": r.manipulations,
            "seconds": dt,
        }

    results: dict[str, dict] = {}
    md: list[str] = []
    for bound in (True, False):
        key = "with_manipulation_bound" if bound else "bare_potentials"
        what = (
            "h = potential/speed + rotation bound + manipulation bound (the planner's default)"
            if bound
            else "h = potential/speed + rotation bound (the paper's potentials alone)"
        )
        kinds = ("euclid", "wavefront", "skeleton")
        t2 = {k: {g: run(k, g, 1.0, 1.0, bound) for g in goals} for k in kinds}
        ref = t2["euclid"][goals[0]]["N_open"]
        t2_norm = {k: [t2[k][g]["N_open"] / ref for g in goals] for k in t2}
        t3: dict[str, dict] = {}
        for kind in ("skeleton", "wavefront"):
            rows = {f"{wg:g},{wh:g}": run(kind, goals[-1], wg, wh, bound) for wg, wh in STRATEGIES}
            dij = rows["1,0"]
            for r in rows.values():
                r["N_open_norm"] = r["N_open"] / dij["N_open"]
                r["f_norm"] = r["cost_s"] / dij["cost_s"]
            t3[kind] = rows
        results[key] = {
            "table2": {"raw": t2, "N_open_norm": t2_norm},
            "table3": t3,
        }
        md += [f"### {what}", ""]
        md += ["Table 2 (N_open normalized to (A) Euclid / Goal1; paper in brackets)", ""]
        md.append("| Potential | " + " | ".join(goals) + " |")
        md.append("|---|" + "---|" * len(goals))
        for k in t2_norm:
            cells = [f"{v:.2f} [{p:.2f}]" for v, p in zip(t2_norm[k], PAPER_T2[k], strict=True)]
            md.append(f"| {LABEL[k]} | " + " | ".join(cells) + " |")
        md.append("")
        md.append(
            "Raw N_open: "
            + "; ".join(
                f"{LABEL[k]} " + ", ".join(str(t2[k][g]["N_open"]) for g in goals) for k in t2
            )
        )
        for kind in ("skeleton", "wavefront"):
            md += [
                "",
                f"Table 3 ({goals[-1]}, {LABEL[kind]}; normalized to Dijkstra; paper in brackets)",
                "",
            ]
            md.append("| Strategy | w_g | w_h | N_open | f | N_open (raw) | cost (s) |")
            md.append("|---|---|---|---|---|---|---|")
            for i, (wg, wh) in enumerate(STRATEGIES, start=1):
                r = t3[kind][f"{wg:g},{wh:g}"]
                pn, pf = PAPER_T3[(wg, wh)]
                md.append(
                    f"| {i} | {wg:.1f} | {wh:.1f} | {r['N_open_norm']:.2f} [{pn:.2f}] | "
                    f"{r['f_norm']:.2f} [{pf:.2f}] | {r['N_open']} | {r['cost_s']:.1f} |"
                )
        md.append("")
    markdown = "\n".join(md)
    out = {
        "bench": "route_tables",
        "map": m.name,
        "grid": [cs.frame.nx, cs.frame.ny, cs.heading_bins],
        "params": dataclasses.asdict(base),
        "paper": {
            "table2": PAPER_T2,
            "table3": {f"{k[0]:g},{k[1]:g}": v for k, v in PAPER_T3.items()},
        },
        **results,
        "markdown": markdown,
    }
    log(markdown)
    if args.markdown:
        print(markdown)
    else:
        print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
