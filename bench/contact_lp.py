"""Contact-force LP with and without contact friction: prints ONE JSON object on stdout.

For μ_contact ∈ {0, 0.3} and 4 and 8 contacts, the same seeded random LPs
(``tests.support.transport_cases.random_lp``) go through:

- ``highs``: scipy's HiGHS ``linprog`` (the reference and the fallback);
- osqp variants of :class:`controller.planning.contact_lp.ContactForceLP`, one knob changed at a
  time from the shipped setting (``default``: warm start, eps 1e-6, 1000 iterations, rescue on):
  ``no_rescue`` (what shipped before: everything osqp does not finish goes to HiGHS),
  ``max_iter_4000``, ``eps_1e-5``, ``polish`` (the active-set re-solve on every answer),
  ``cold`` (no warm start), ``scaling_25`` (more Ruiz scaling iterations), and
  ``warm_from_frictionless`` (each friction LP first solved without friction by a second
  workspace whose forces seed the friction solve; the time counts both solves).

Per variant: median and p95 wall time per problem (µs), the share handed to HiGHS, the share
rescued, disagreements with HiGHS (status, or objective off by more than 1e-4 relative).
Ratios are against HiGHS timed in the same process. Usage: ``python bench/contact_lp.py
[--problems N]`` (default 400 per cell).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.planning.contact_lp import ContactForceLP, solve_reference  # noqa: E402
from tests.support.transport_cases import random_lp  # noqa: E402


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class FrictionlessWarm:
    """Solve without friction first; its forces warm-start the friction workspace."""

    def __init__(self, n: int):
        self.free = ContactForceLP(n)
        self.lp = ContactForceLP(n, friction=True)

    def solve(self, **args):
        first = self.free.solve(**{**args, "contact_friction": 0.0})
        if first.feasible and self.lp._prob is not None:
            x = np.zeros(2 * self.lp.n_max)
            scale = float(np.max(np.asarray(args["max_force"]) * args["active"]))
            x[: len(first.normal)] = first.normal / max(scale, 1e-12)
            self.lp._prob.warm_start(x=x)
        return self.lp.solve(**args)

    @property
    def fallbacks(self) -> int:
        return self.lp.fallbacks

    @property
    def rescued(self) -> int:
        return self.lp.rescued

    @property
    def solves(self) -> int:
        return self.lp.solves


def variants(n: int, friction: bool) -> dict:
    out = {
        "default": lambda: ContactForceLP(n, friction=friction),
        "no_rescue": lambda: ContactForceLP(n, friction=friction, rescue=False),
        "max_iter_4000": lambda: ContactForceLP(n, friction=friction, max_iter=4000),
        "eps_1e-5": lambda: ContactForceLP(n, friction=friction, eps=1e-5),
        "polish": lambda: ContactForceLP(n, friction=friction, polish=True),
    }

    def with_settings(**kw):
        def make():
            lp = ContactForceLP(n, friction=friction)
            lp.SETTINGS = {**ContactForceLP.SETTINGS, **kw}
            return lp

        return make

    out["cold"] = with_settings(warm_starting=False)
    out["scaling_25"] = with_settings(scaling=25)
    if friction:
        out["warm_from_frictionless"] = lambda: FrictionlessWarm(n)
    return out


def cell(n: int, mu: float, count: int) -> dict:
    rng = np.random.default_rng(1000 + 10 * n + int(mu * 10))
    problems = [random_lp(rng, n, mu) for _ in range(count)]
    refs, t_ref = [], []
    for args in problems:
        t0 = time.perf_counter()
        refs.append(solve_reference(**{k: v for k, v in args.items() if k != "length"}))
        t_ref.append(time.perf_counter() - t0)
    out = {
        "problems": count,
        "feasible_share": round(sum(r.feasible for r in refs) / count, 3),
        "highs": {"median_us": round(float(np.median(t_ref)) * 1e6, 1)},
    }
    for name, make in variants(n, mu > 0).items():
        lp = make()
        ts, bad = [], 0
        for args, ref in zip(problems, refs, strict=True):
            t0 = time.perf_counter()
            res = lp.solve(**args)
            ts.append(time.perf_counter() - t0)
            off = ref.feasible and abs(res.total - ref.total) > 1e-4 * max(ref.total, 1e-9)
            bad += res.status != ref.status or off
        med = float(np.median(ts)) * 1e6
        out[name] = {
            "median_us": round(med, 1),
            "p95_us": round(float(np.percentile(ts, 95)) * 1e6, 1),
            "highs_fallback_share": round(lp.fallbacks / max(lp.solves, 1), 4),
            "rescued_share": round(getattr(lp, "rescued", 0) / max(lp.solves, 1), 4),
            "disagreements": int(bad),
            "speedup_vs_highs": round(out["highs"]["median_us"] / max(med, 1e-9), 2),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--problems", type=int, default=400)
    args = ap.parse_args()
    out: dict = {"bench": "contact_lp", "load_average": [round(x, 2) for x in os.getloadavg()]}
    for n in (4, 8):
        for mu in (0.0, 0.3):
            log(f"{n} contacts, mu_contact {mu} ...")
            out[f"n{n}_mu{mu}"] = cell(n, mu, args.problems)
    d = {k: v["default"] for k, v in out.items() if k.startswith("n")}
    out["summary"] = {
        "median_us_by_cell": {k: v["median_us"] for k, v in d.items()},
        "highs_fallback_share_by_cell": {k: v["highs_fallback_share"] for k, v in d.items()},
        "fallback_goal_1pct_met": all(v["highs_fallback_share"] < 0.01 for v in d.values()),
        "friction_slowdown_8": round(d["n8_mu0.3"]["median_us"] / d["n8_mu0.0"]["median_us"], 2),
    }
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
