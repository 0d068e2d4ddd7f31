"""Transport benchmark: prints ONE JSON object on stdout (progress on stderr).

1. The contact-force LP (:mod:`controller.planning.contact_lp`): the warm-started osqp solver
   against scipy's HiGHS ``linprog`` on the same problems, at 4 and 8 contacts, two streams:
   the LPs the annealer actually solves while planning (recorded from seeded plans: consecutive
   problems are similar, as in the closed loop) and independent random instances. Median and
   p95 in microseconds, the share osqp hands to HiGHS, the largest objective gap.
2. The local planners (:func:`controller.planning.transport.plan_local`) on seeded planning
   scenarios: plan time (median, p95) for ``sa`` (cold: a fresh call; warm: a
   :class:`TransportPlanner` re-planning the same mission each tick), ``downhill`` and
   ``serpentine``, and the energy each reaches (lower is better), also at larger iteration
   budgets for sa/downhill.
3. ``closed_loop(scenarios, strategies, run_one)``: the hook for the pybullet comparison
   (success rate, transport time, lateral deviation, contact-force impulse, rearrangements,
   local-plan time). It aggregates whatever ``run_one(scenario, strategy) -> dict`` returns;
   this script has no closed-loop runner yet, so the JSON says ``closed_loop: null``.

Timings are wall-clock medians on a shared 2-core machine (the load average is reported): trust
the ratios more than the absolute figures. Usage: ``python bench/transport.py [--quick]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.planning.contact_lp import ContactForceLP, solve_reference  # noqa: E402
from controller.planning.transport import TransportPlanner, plan_local  # noqa: E402
from controller.planning.transport_types import TransportParams  # noqa: E402
from tests.support.transport_cases import diamond_case, push_case, random_lp  # noqa: E402


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def stats_us(ts: list[float], cpu: list[float] | None = None) -> dict[str, float]:
    a = np.asarray(ts) * 1e6
    out = {
        "median_us": round(float(np.median(a)), 1),
        "p95_us": round(float(np.percentile(a, 95)), 1),
    }
    if cpu is not None:
        out["cpu_median_us"] = round(float(np.median(cpu)) * 1e6, 1)
    return out


def stats_ms(ts: list[float], cpu: list[float] | None = None) -> dict[str, float]:
    a = np.asarray(ts) * 1e3
    out = {
        "median_ms": round(float(np.median(a)), 2),
        "p95_ms": round(float(np.percentile(a, 95)), 2),
    }
    if cpu is not None:
        out["cpu_median_ms"] = round(float(np.median(cpu)) * 1e3, 2)
    return out


class Clock:
    """Wall and process CPU time of a block (CPU time suffers less on the shared machine)."""

    def __enter__(self):
        self.w, self.c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.w
        self.cpu = time.process_time() - self.c


# --------------------------------------------------------------------------- scenarios


def _with_actions(state, actions):
    robots = tuple(
        dataclasses.replace(r, action=a) for r, a in zip(state.robots, actions, strict=True)
    )
    return dataclasses.replace(state, robots=robots)


def scenarios() -> list[dict]:
    """Seeded planning situations (pure planner, no physics): name, robots, state."""
    out = [
        {"name": "crate-8-strong", "state": push_case(8, max_force=10.0)},
        {"name": "crate-8-weak", "state": push_case(8, max_force=4.0)},
        {"name": "crate-8-weak-shuffled", "state": push_case(8, max_force=4.0, seed=3)},
        {"name": "crate-6-weak", "state": push_case(6, max_force=4.0)},
        {"name": "crate-8-turn", "state": push_case(8, max_force=6.0, goal=(5.0, 3.5, 1.2))},
        {"name": "crate-4", "state": push_case(4, max_force=6.0, seed=1)},
        {
            "name": "diamond-both-following",
            "state": _with_actions(diamond_case(), ["follow", "follow"]),
        },
    ]
    for s in out:
        s["robots"] = len(s["state"].robots)
    return out


# --------------------------------------------------------------------------- the LP


class RecordingLP(ContactForceLP):
    """A ContactForceLP that keeps the arguments of every solve."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.calls: list[tuple] = []

    def solve(self, *args, **kw):
        self.calls.append((args, kw))
        return super().solve(*args, **kw)


def recorded_lps(n_robots: int, limit: int) -> list[dict]:
    """The LPs seeded SA plans solve (as keyword dicts), padded to exactly n_robots contacts
    with inactive ones so the workspace size is the one measured."""
    out: list[dict] = []
    cases = [s for s in scenarios() if s["robots"] == n_robots] or [scenarios()[0]]
    seed = 0
    while len(out) < limit and seed < 40:
        for case in cases:
            lp = RecordingLP(n_robots)
            plan_local(
                case["state"], TransportParams(iterations=100), np.random.default_rng(seed), lp=lp
            )
            for args, _ in lp.calls:
                pts, nrm, fmax, act, w, mu, length = args
                k = n_robots - len(pts)
                out.append(
                    dict(
                        points=np.vstack([pts, np.zeros((k, 2))]),
                        normals=np.vstack([nrm, np.tile([1.0, 0.0], (k, 1))]),
                        max_force=np.concatenate([fmax, np.zeros(k)]),
                        active=np.concatenate([act, np.zeros(k, bool)]),
                        wrench=w,
                        contact_friction=mu,
                        length=length,
                    )
                )
        seed += 1
    return out[:limit]


def bench_lp(problems: list[dict], n: int) -> dict:
    warm = ContactForceLP(n)
    t_osqp, c_osqp, t_highs, c_highs, gap, agree, feasible = [], [], [], [], 0.0, 0, 0
    for args in problems:  # one pass first so the timed pass is warm, like the planner
        warm.solve(**args)
    warm.solves = warm.fallbacks = 0
    for args in problems:
        with Clock() as a:
            ours = warm.solve(**args)
        with Clock() as b:
            ref = solve_reference(**{k: v for k, v in args.items() if k != "length"})
        t_osqp.append(a.wall)
        c_osqp.append(a.cpu)
        t_highs.append(b.wall)
        c_highs.append(b.cpu)
        agree += ours.status == ref.status
        feasible += ref.feasible
        if ours.feasible and ref.feasible:
            gap = max(gap, abs(ours.total - ref.total) / max(ref.total, 1e-9))
    so, sh = stats_us(t_osqp, c_osqp), stats_us(t_highs, c_highs)
    return {
        "problems": len(problems),
        "feasible_share": round(feasible / max(len(problems), 1), 3),
        "osqp_warm": so,
        "highs_linprog": sh,
        "speedup_median": round(sh["median_us"] / max(so["median_us"], 1e-9), 1),
        "same_feasibility": f"{agree}/{len(problems)}",
        "max_objective_rel_gap": float(f"{gap:.2e}"),
        "highs_fallback_share": round(warm.fallbacks / max(warm.solves, 1), 4),
    }


# --------------------------------------------------------------------------- the planners


def time_plans(state, params: TransportParams, reps: int):
    """(wall times, cpu times, energies) of fresh plans with seeds 0..reps-1."""
    ts, cs, es = [], [], []
    for seed in range(reps):
        with Clock() as c:
            plan = plan_local(state, params, np.random.default_rng(seed))
        ts.append(c.wall)
        cs.append(c.cpu)
        es.append(plan.energy.total)
    return ts, cs, es


def time_ticks(state, params: TransportParams, ticks: int):
    """A TransportPlanner re-planning the same state every tick (warm: LP, scans, last plan)."""
    planner = TransportPlanner(params)
    planner.plan(state, np.random.default_rng(0))
    ts, cs = [], []
    for t in range(ticks):
        with Clock() as c:
            planner.plan(state, np.random.default_rng(t + 1), elapsed=0.05)
        ts.append(c.wall)
        cs.append(c.cpu)
    return ts, cs


def bench_planners(cases: list[dict], reps: int, budgets: list[int]) -> dict:
    out: dict = {}
    for case in cases:
        name, st = case["name"], case["state"]
        log(f"  {name} ...")
        row: dict = {"robots": case["robots"]}
        for strategy in ("sa", "downhill", "serpentine"):
            ts, cs, es = time_plans(st, TransportParams(strategy=strategy), reps)
            row[strategy] = {**stats_ms(ts, cs), "energy_median": round(float(np.median(es)), 3)}
        row["sa_warm_ticks"] = stats_ms(*time_ticks(st, TransportParams(), reps))
        for it in budgets:
            cool = float(1e-3 ** (1.0 / it))  # T falls to 1e-3 T_0 over the budget
            for strategy in ("sa", "downhill"):
                p = TransportParams(strategy=strategy, iterations=it, cooling=cool)
                ts, cs, es = time_plans(st, p, max(3, reps // 3))
                row[f"{strategy}_{it}"] = {
                    **stats_ms(ts, cs),
                    "energies": [round(e, 2) for e in es],
                }
        out[name] = row
    return out


def energy_summary(planners: dict, budgets: list[int]) -> dict:
    """Per budget: on how many (scenario, seed) pairs sa ended lower / equal / higher than
    downhill."""
    out = {}
    for it in budgets:
        lower = equal = higher = 0
        for row in planners.values():
            for a, b in zip(
                row[f"sa_{it}"]["energies"], row[f"downhill_{it}"]["energies"], strict=True
            ):
                lower += a < b - 1e-6
                higher += a > b + 1e-6
                equal += abs(a - b) <= 1e-6
        out[str(it)] = {"sa_lower": lower, "equal": equal, "sa_higher": higher}
    return out


# --------------------------------------------------------------------------- closed loop hook


def closed_loop(
    cases: list[dict],
    strategies: tuple[str, ...],
    run_one: Callable[[dict, str], dict] | None,
) -> dict | None:
    """Aggregate closed-loop runs: ``run_one(scenario, strategy)`` runs one scenario to the end
    and returns a dict with ``transported`` (bool), ``transport_time_s``,
    ``lateral_deviation_rms_m``, ``max_lateral_deviation_m``, ``impulse_ns`` (Σ|f|·dt),
    ``rearrangements`` and ``plan_times_s`` (list). Returns per strategy: success rate and
    medians over the delivered runs; None without a runner."""
    if run_one is None:
        return None
    out = {}
    for strategy in strategies:
        runs = [run_one(case, strategy) for case in cases]
        ok = [r for r in runs if r.get("transported")]

        def med(key: str, rows: list[dict] = ok) -> float | None:
            vals = [r[key] for r in rows if r.get(key) is not None]
            return round(float(np.median(vals)), 4) if vals else None

        plan_times = [t for r in runs for t in r.get("plan_times_s", [])]
        out[strategy] = {
            "runs": len(runs),
            "success_rate": round(len(ok) / max(len(runs), 1), 3),
            "transport_time_s": med("transport_time_s"),
            "lateral_deviation_rms_m": med("lateral_deviation_rms_m"),
            "max_lateral_deviation_m": med("max_lateral_deviation_m"),
            "impulse_ns": med("impulse_ns"),
            "rearrangements": med("rearrangements", runs),
            "plan_time": stats_ms(plan_times) if plan_times else None,
        }
    return out


def main(run_one: Callable[[dict, str], dict] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = ap.parse_args()
    reps = 5 if args.quick else 15
    n_lp = 300 if args.quick else 1000
    budgets = [100, 300] if args.quick else [100, 300, 1000]
    out: dict = {"bench": "transport", "load_average": [round(x, 2) for x in os.getloadavg()]}
    out["lp"] = {}
    for n in (4, 8):
        log(f"LP at {n} contacts ...")
        rng = np.random.default_rng(n)
        out["lp"][str(n)] = {
            "planner_stream": bench_lp(recorded_lps(n, n_lp), n),
            "random_stream": bench_lp([random_lp(rng, n) for _ in range(n_lp // 2)], n),
        }
    log("planners ...")
    cases = scenarios()
    out["planners"] = bench_planners(cases, reps, budgets)
    out["sa_vs_downhill"] = energy_summary(out["planners"], budgets)
    out["closed_loop"] = closed_loop(cases, ("sa", "serpentine", "downhill"), run_one)
    lp8 = out["lp"]["8"]["planner_stream"]["osqp_warm"]["median_us"]
    sa8 = [r["sa"]["median_ms"] for r in out["planners"].values() if r["robots"] == 8]
    warm8 = [r["sa_warm_ticks"]["median_ms"] for r in out["planners"].values() if r["robots"] == 8]
    out["goals"] = {
        "lp_8_contacts_warm_median_us": lp8,
        "lp_goal_150us_met": lp8 < 150,
        "sa_plan_8_robots_median_ms": round(float(np.median(sa8)), 2),
        "sa_plan_8_robots_warm_tick_median_ms": round(float(np.median(warm8)), 2),
        "sa_goal_50ms_met": float(np.median(warm8)) < 50,
    }
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
