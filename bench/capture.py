"""Capture-GA benchmark: prints ONE JSON object on stdout (progress on stderr).

- BLAS threads: this process pins OpenBLAS/OpenMP to one thread before numpy loads (the GA does
  no matrix products, so the thread count should not matter: the paper budget is also timed in a
  child process with the default threads, same code, same seeds);
- evaluations/s of the objective (population of 60 sparse strings, 60-node boundary);
- seconds for the paper's budget (60 x 600 = 36 000 evaluations) on the 60-node boundary (the
  fleet.toml L-shaped crate at a spacing giving 60 candidates) and on a 190-node one, medians;
- optimum hits against brute force (subsets of 3..6 nodes; the GA limited to 6 robots, the same
  space) on a FRESH seeded suite of polygons (half concave, 14..30 candidates; seed 7919, which
  the tests do not use), within the paper's budget, for:
  ours (infeasible strings ranked by their violation count), ``paper`` (``capture.ga =
  "paper"``: Sharma's GA as published, ``run_paper_ga``), ours with the old tie
  (``-1e30 - v``: every infeasible string equal in float64), both over ``--ga-seeds`` seed sets
  (hits over all runs, and per seed set), pygad (one seed set) with the paper's settings
  (random initial population, per-gene mutation 0.12) and pygad as its documentation recommends
  (a user-given initial_population, here sparse strings of 3..6 robots, and per-gene mutation
  probability 1/K); every GA gets the same ranked fitness and the same budget;
- large boundaries, each in a fresh child process (peak RSS = that process's ru_maxrss, with
  the RSS after imports for reference): ``plan_capture`` end to end (candidates, GA, diagnosis,
  LP certificate) on squares of 19 m at 0.1 m (K = 760), 20 m at 0.05 m (K = 1600) and 20 m at
  0.04 m (K = 2000), robots 0.1 m, six robots; and a spacing past the node budget (the plan's
  reason must name capture.spacing).

The machine is shared: medians, the load average is reported. Usage:
``python bench/capture.py [--repeats N] [--polygons N]``; the suite alone on a fresh seed:
``--suite-only --suite-seed S --gas ours,paper``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy loads (a child may ask for the defaults)

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller import geometry  # noqa: E402
from controller.planning.capture import (  # noqa: E402
    PENALTY,
    CaptureParams,
    evaluate,
    make_problem,
    plan_capture,
    rank_strings,
    run_ga,
    run_paper_ga,
)
from tests.support.capture_oracle import brute_force_capture  # noqa: E402

L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)
SUITE_SEED = 7919  # tests/unit/test_capture.py uses 2024
GA_SEED = 50_000  # + polygon index
MAX_ROBOTS = 6  # the brute force's largest subset
LARGE = {760: (19.0, 0.1), 1600: (20.0, 0.05), 2000: (20.0, 0.04)}  # K: (square side, spacing)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def tied_rank(f, v):
    """The ranking before the fix: ``-1e30 - v`` is -1e30 for every v in float64."""
    return np.where(v == 0, f, -1e30 - v)


def problem_with(nodes: int):
    for spacing in np.linspace(0.2, 0.004, 4000):
        prob = make_problem(L_SHAPE, 0.1, CaptureParams(spacing=float(spacing)))
        if len(prob.cand.points) >= nodes:
            return prob
    raise RuntimeError(f"no spacing gives {nodes} nodes")


def random_polygons(count: int, rng: np.random.Generator, closure: str = "exact"):
    """``count`` polygons with 14-30 candidate nodes whose exact form-closure optimum exists
    (the same draws whatever ``closure``); ``closure = "paper"``: each judged under the
    paper's constraints instead (§2.5: translation closure, moments both ways, one robot per
    edge, spacing), its brute-force optimum under them."""
    out = []
    while len(out) < count:
        concave = len(out) % 2 == 1
        n = int(rng.integers(4, 8))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        rad = rng.uniform(0.35, 1.0, n) if concave else np.ones(n)
        poly = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
        if not concave:
            poly = geometry.convex_hull(poly)
        poly = geometry.ensure_ccw(poly)
        if geometry.self_intersection(poly) is not None or abs(geometry.signed_area(poly)) < 0.3:
            continue
        per = float(np.sum(np.linalg.norm(np.roll(poly, -1, 0) - poly, axis=1)))
        params = CaptureParams(spacing=per / rng.uniform(14, 32))
        k = len(make_problem(poly, 0.05, params).cand.points)
        if not 14 <= k <= 30:
            continue
        bf, _ = brute_force_capture(poly, 0.05, params)
        if bf <= -1e19:
            continue
        if closure == "paper":
            params = dataclasses.replace(params, closure="paper")
            bf, _ = brute_force_capture(poly, 0.05, params)
        out.append((poly, params, bf, k))
        log(f"polygon {len(out)}: {k} nodes, optimum {bf:.4g}")
    return out


def sparse_population(k: int, size: int, rng: np.random.Generator) -> np.ndarray:
    x = np.zeros((size, k), int)
    for r in range(size):
        x[r, rng.choice(k, int(rng.integers(3, MAX_ROBOTS + 1)), replace=False)] = 1
    return x


def pygad_run(prob, seed: int, recommended: bool) -> float:
    """pygad on the same objective and budget; the best feasible objective (PENALTY if none)."""
    import pygad

    k = len(prob.cand.points)
    p = prob.params

    def fitness(ga, solutions, idx):
        f, v = evaluate(prob, np.asarray(solutions, dtype=bool).reshape(-1, k))
        return rank_strings(f, v).tolist()

    extra = (
        {
            "initial_population": sparse_population(k, p.population, np.random.default_rng(seed)),
            "mutation_probability": 1.0 / k,
        }
        if recommended
        else {"sol_per_pop": p.population, "num_genes": k, "mutation_probability": p.mutation}
    )
    ga = pygad.GA(
        num_generations=p.generations,
        num_parents_mating=p.population // 2,
        gene_space=[0, 1],
        gene_type=int,
        fitness_func=fitness,
        fitness_batch_size=p.population,
        crossover_probability=p.crossover,
        keep_elitism=1,
        random_seed=seed,
        suppress_warnings=True,
        **extra,
    )
    ga.run()
    sol, _, _ = ga.best_solution()
    f, v = evaluate(prob, np.asarray(sol, dtype=bool)[None])
    return float(f[0]) if v[0] == 0 else PENALTY


def figures(found: list[float], polys) -> dict:
    gaps = [
        (bf - f) / bf if f > PENALTY / 2 else 1.0
        for f, (_, _, bf, _) in zip(found, polys, strict=True)
    ]
    hits = sum(g <= 1e-9 for g in gaps)
    return {
        "hits": hits,
        "hit_rate": hits / len(polys),
        "median_gap": statistics.median(gaps),
        "max_gap": max(gaps),
    }


GAS = ("ours", "paper", "ours_tied", "pygad_paper", "pygad_doc")


def one_ga(name: str, prob, seed: int) -> float:
    """The best feasible objective one GA finds on ``prob`` within the paper's budget."""
    if name == "ours":
        return run_ga(prob, np.random.default_rng(seed)).objective
    if name == "paper":  # capture.ga = "paper": Sharma's GA as published
        return run_paper_ga(prob, np.random.default_rng(seed)).objective
    if name == "ours_tied":
        return run_ga(prob, np.random.default_rng(seed), rank=tied_rank).objective
    return pygad_run(prob, seed, recommended=name == "pygad_doc")


def suite_figures(
    count: int,
    ga_seeds: int,
    suite_seed: int = SUITE_SEED,
    gas: tuple[str, ...] = GAS,
    closure: str = "exact",
) -> dict:
    """Hits on the fresh suite: pygad once per polygon (seed GA_SEED + i), ours, paper and
    ours_tied with ``ga_seeds`` seeds per polygon (GA_SEED + 1000 s + i; s = 0 is pygad's)."""
    polys = random_polygons(count, np.random.default_rng(suite_seed), closure)
    runs: dict[str, list[float]] = {name: [] for name in gas}
    seconds: dict[str, list[float]] = {name: [] for name in gas}
    repeat = {"ours": ga_seeds, "paper": ga_seeds, "ours_tied": ga_seeds}
    repeat.update(pygad_paper=1, pygad_doc=1)
    for s in range(ga_seeds):
        for i, (poly, params, bf, _) in enumerate(polys):
            prob = make_problem(poly, 0.05, params, max_robots=MAX_ROBOTS)
            for name in (n for n in gas if s < repeat[n]):
                t0 = time.perf_counter()
                runs[name].append(one_ga(name, prob, GA_SEED + 1000 * s + i))
                seconds[name].append(time.perf_counter() - t0)
            found = ", ".join(f"{n} {v[-1]:.4g}" for n, v in runs.items())
            log(f"seed set {s}, polygon {i + 1}: optimum {bf:.4g}, {found}")
    out: dict = {"polygons": len(polys), "seed": suite_seed, "nodes": [k for *_, k in polys],
                 "closure": closure}  # fmt: skip
    for name in gas:
        per_seed = [
            figures(runs[name][j * len(polys) : (j + 1) * len(polys)], polys)
            for j in range(repeat[name])
        ]
        out[name] = {
            **figures(runs[name], polys * repeat[name]),
            "runs": len(runs[name]),
            "hits_per_seed_set": [f["hits"] for f in per_seed],
            "median_seconds": statistics.median(seconds[name]),
        }
    if "pygad_doc" in out and "ours" in out:
        out["pygad_doc_over_ours_seconds"] = (
            out["pygad_doc"]["median_seconds"] / out["ours"]["median_seconds"]
        )
    return out


def budget_timing(repeats: int) -> dict:
    """The paper's budget on 60 and 190 nodes: median wall and CPU seconds (this process's
    threads; CPU time is what the run costs when other work shares the cores)."""
    out = {}
    for nodes in (60, 190):
        prob = problem_with(nodes)
        secs, cpu, evals = [], [], 0
        for r in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            res = run_ga(prob, np.random.default_rng(r))
            secs.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            evals = res.evaluations
        out[f"K{len(prob.cand.points)}"] = {
            "evaluations": evals,
            "median_seconds": statistics.median(secs),
            "median_cpu_seconds": statistics.median(cpu),
            "seconds": secs,
        }
    return out


def evaluations_per_s(repeats: int) -> float:
    prob = problem_with(60)
    k = len(prob.cand.points)
    pop = sparse_population(k, 60, np.random.default_rng(0)).astype(bool)
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(100):
            evaluate(prob, pop)
        rates.append(6000 / (time.perf_counter() - t0))
    return statistics.median(rates)


def large_run(nodes: int) -> dict:
    """One ``plan_capture`` on a big square (in its own process: its peak RSS is this run's)."""
    side, spacing = LARGE[nodes]
    square = np.array([[0, 0], [side, 0], [side, side], [0, side]], dtype=float)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    plan = plan_capture(square, 0.1, CaptureParams(spacing=spacing), np.random.default_rng(0), 6)
    sec = time.perf_counter() - t0
    return {
        "nodes": len(plan.candidates),
        "seconds": sec,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "rss_after_imports_mb": rss0,
        "feasible": plan.feasible,
        "robots": plan.robots_needed,
        "objective": plan.objective,
        "evaluations": plan.evaluations,
    }


def over_budget() -> dict:
    square = np.array([[0, 0], [20.0, 0], [20.0, 20.0], [0, 20.0]])
    t0 = time.perf_counter()
    plan = plan_capture(square, 0.1, CaptureParams(spacing=0.001), np.random.default_rng(0), 6)
    return {"seconds": time.perf_counter() - t0, "feasible": plan.feasible, "reason": plan.reason}


def child(args: list[str], pinned: bool) -> dict:
    env = dict(os.environ)
    if not pinned:
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env.pop(var, None)
    out = subprocess.run(
        [sys.executable, __file__, *args], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--polygons", type=int, default=100)
    ap.add_argument("--ga-seeds", type=int, default=3, help="seed sets for our GA on the suite")
    ap.add_argument("--large", type=int, default=0, help=argparse.SUPPRESS)  # child: one K
    ap.add_argument("--budget-only", action="store_true", help=argparse.SUPPRESS)  # child
    ap.add_argument("--suite-only", action="store_true", help="only the optimum-hit suite")
    ap.add_argument("--suite-seed", type=int, default=SUITE_SEED, help="a fresh suite: new seed")
    ap.add_argument("--gas", default=",".join(GAS), help="GAs on the suite (comma-separated)")
    ap.add_argument(
        "--closure",
        default="exact",
        choices=("exact", "paper"),
        help="the suite's constraints: exact form closure, or the paper's (§2.5)",
    )
    args = ap.parse_args()
    if args.suite_only:
        load0 = os.getloadavg()
        suite = suite_figures(
            args.polygons, args.ga_seeds, args.suite_seed, tuple(args.gas.split(",")),
            args.closure,
        )  # fmt: skip
        load = {"start": load0, "end": os.getloadavg()}
        print(json.dumps({"bench": "capture", "load_average": load, "suite": suite}, indent=1))
        return
    if args.large:
        print(json.dumps(large_run(args.large)))
        return
    if args.budget_only:
        print(json.dumps(budget_timing(args.repeats)))
        return

    load0 = os.getloadavg()
    log("paper budget, one BLAS thread ...")
    pinned = budget_timing(args.repeats)
    log("paper budget, default BLAS threads (child process) ...")
    default = child(["--budget-only", "--repeats", str(args.repeats)], pinned=False)
    rate = evaluations_per_s(args.repeats)
    large = {}
    for nodes in LARGE:
        log(f"plan_capture end to end at K = {nodes} (child process) ...")
        large[f"K{nodes}"] = child(["--large", str(nodes)], pinned=True)
    suite = suite_figures(args.polygons, args.ga_seeds)
    k60 = next(iter(pinned))
    out = {
        "bench": "capture",
        "load_average": {"start": load0, "end": os.getloadavg()},
        "evaluations_per_s": rate,
        "paper_budget": {
            "one_thread": pinned,
            "default_threads": default,
            "goal": "< 0.2 s median at K = 60, one BLAS thread",
            "goal_met": pinned[k60]["median_seconds"] < 0.2,
            "goal_met_cpu": pinned[k60]["median_cpu_seconds"] < 0.2,
        },
        "large": large,
        "large_goal_met": large["K760"]["seconds"] < 2
        and all(v["peak_rss_mb"] < 500 for v in large.values()),
        "over_budget": over_budget(),
        "suite": suite,
        "goal_hit_rate_met": suite["ours"]["hit_rate"] >= 0.97,
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
