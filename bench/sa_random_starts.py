"""Vass's claim, decided (issue 34, item 7): does simulated annealing escape the local minima
that hold a downhill search, from random starts? Prints ONE JSON object on stdout (progress on
stderr).

Vass et al. (§3, after Code 1): "there are many local minima, which can be shown by executing
downhill searches from different random generated initial V matrices"; SA is used to avoid
them. Here each *pair* is one planning problem and one random start matrix, planned by ``sa``
and by ``downhill`` (the same generator seed, so the same start; only the acceptance of uphill
moves differs), and the pair is won by the lower energy (Vass Eq. 3; ties when equal).

**Problems** (drawn by ``--seed``, default 20261129, a seed no setting was tuned on): the
transport tests' seeded situations (``tests/support/transport_cases.push_case``) with the
object one of the L crate, a 0.6 x 0.4 m box and the diamond, 4-8 robots, force limits
3-8 N, mass 2-6 kg, floor friction 0.15-0.35 and the robots shuffled over its faces. Only
problems the planner can solve are kept: a downhill plan from the default start (the LP's
least-force set) with no infeasible interval and no collision; the others (too heavy for the
robots on the pushing faces, robots overlapping on a small object) are drawn again, and
counted (``rejected``). A random start then tests what Vass says SA is for: getting out of
the minima a start leaves the search in.

**Settings**: ``default`` (the config's: 100 iterations, T0 0.3, cooling 0.95 per iteration,
Vass's example schedule) and ``long`` (300 iterations, T0 1.0, cooling 0.985: a hotter,
longer anneal, the earlier quick check's).

**Tests**: the exact sign test on the pairs that differ (binomial, two-sided) and Wilcoxon's
signed-rank test on the energy differences with n (``bench/stats.py``), Holm over the two
settings. **The rule, fixed before the run**: a setting favours SA when SA wins more pairs and
the Holm-adjusted sign test gives p < 0.05; downhill the other way round; else undecided.
Usage: ``python bench/sa_random_starts.py [--pairs 240] [--seed N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.stats import holm, signed_rank  # noqa: E402
from controller.planning.transport import plan_local  # noqa: E402
from controller.planning.transport_types import TransportParams  # noqa: E402
from tests.support.transport_cases import BOX, DIAMOND, L_SHAPE, push_case  # noqa: E402

SHAPES = {"L": L_SHAPE, "box": BOX, "diamond": DIAMOND}
SETTINGS = {
    "default": TransportParams(initial_actions="random"),
    "long": TransportParams(
        initial_actions="random", iterations=300, initial_temperature=1.0, cooling=0.985
    ),
}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def solvable(p: dict) -> bool:
    """A downhill plan from the LP's start pushes the whole horizon without a collision."""
    plan = plan_local(case(p), TransportParams(strategy="downhill"), np.random.default_rng(0))
    return plan.energy.infeasible == 0 and plan.energy.collisions == 0


def case(p: dict):
    return push_case(p["robots"], p["mass"], p["mu"], p["max_force"], obj=SHAPES[p["shape"]],
                     seed=p["layout"])  # fmt: skip


def problems(n: int, seed: int) -> tuple[list[dict], int]:
    """``n`` solvable problems drawn by ``seed``, and how many unsolvable ones were drawn."""
    rng = np.random.default_rng(seed)
    out: list[dict] = []
    names = list(SHAPES)
    rejected = 0
    k = 0
    while len(out) < n:
        k += 1
        p = {
            "shape": names[k % len(names)],
            "robots": int(rng.integers(4, 9)),
            "max_force": round(float(rng.uniform(3.0, 8.0)), 2),
            "mass": round(float(rng.uniform(2.0, 6.0)), 2),
            "mu": round(float(rng.uniform(0.15, 0.35)), 3),
            "layout": int(rng.integers(0, 2**31)),
            "start": int(rng.integers(0, 2**31)),
        }
        if solvable(p):
            out.append(p)
        else:
            rejected += 1
    return out, rejected


def pair(p: dict, params: TransportParams) -> dict:
    st = case(p)
    out = {}
    for strategy in ("sa", "downhill"):
        t = time.perf_counter()
        plan = plan_local(st, replace(params, strategy=strategy), np.random.default_rng(p["start"]))
        out[strategy] = {
            "energy": float(plan.energy.total),
            "start_energy": float(plan.start_energy.total),
            "infeasible": int(plan.energy.infeasible),
            "s": time.perf_counter() - t,
        }
    assert out["sa"]["start_energy"] == out["downhill"]["start_energy"]  # the same start
    return out


def summarise(rows: list[dict]) -> dict:
    d = [r["sa"]["energy"] - r["downhill"]["energy"] for r in rows]
    sr = signed_rank(d)
    wins_sa, wins_dh = sr["a_lower"], sr["a_higher"]
    m = wins_sa + wins_dh
    sign_p = float(binomtest(wins_sa, m, 0.5).pvalue) if m else None
    return {
        "pairs": len(rows),
        "sa_lower": wins_sa,
        "downhill_lower": wins_dh,
        "ties": len(rows) - m,
        "sign_test_p": None if sign_p is None else round(sign_p, 4),
        "wilcoxon_p": None if sr["p"] is None else round(sr["p"], 4),
        "median_energy": {
            s: round(float(np.median([r[s]["energy"] for r in rows])), 3)
            for s in ("sa", "downhill")
        },
        "median_start_energy": round(float(np.median([r["sa"]["start_energy"] for r in rows])), 3),
        "plans_with_infeasible_intervals": {
            s: int(sum(r[s]["infeasible"] > 0 for r in rows)) for s in ("sa", "downhill")
        },
        "median_plan_ms": {
            s: round(1e3 * float(np.median([r[s]["s"] for r in rows])), 1)
            for s in ("sa", "downhill")
        },
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=240)
    ap.add_argument("--seed", type=int, default=20261129)
    args = ap.parse_args()
    log("drawing solvable problems")
    probs, rejected = problems(args.pairs, args.seed)
    shapes = {s: sum(p["shape"] == s for p in probs) for s in SHAPES}
    out: dict = {"bench": "sa_random_starts", "seed": args.seed, "rejected": rejected,
                 "shapes": shapes, "load_avg_start": round(os.getloadavg()[0], 2),
                 "settings": {}}  # fmt: skip
    for name, params in SETTINGS.items():
        rows = []
        for k, p in enumerate(probs):
            rows.append(pair(p, params))
            if (k + 1) % 40 == 0:
                log(f"{name}: {k + 1}/{len(probs)}")
        out["settings"][name] = summarise(rows)
    adj = holm([s["sign_test_p"] for s in out["settings"].values()])
    for s, p in zip(out["settings"].values(), adj, strict=True):
        s["sign_test_p_holm"] = None if p is None else round(p, 4)
        if p is not None and p < 0.05:
            s["verdict"] = "sa" if s["sa_lower"] > s["downhill_lower"] else "downhill"
        else:
            s["verdict"] = "undecided"
    out["load_avg_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
