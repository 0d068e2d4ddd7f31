"""Capture-GA benchmark: prints ONE JSON object on stdout (progress on stderr).

- evaluations/s of the vectorised objective (population of 60 sparse strings, 60-node boundary);
- seconds for the paper's budget (60 x 600 = 36 000 evaluations) on a 60-node boundary (the
  fleet.toml L-shaped crate at a spacing giving 60 candidates), median of repeats;
- optimality gap and hit rate against brute force (subsets of 3..6 nodes) over 20 seeded random
  polygons (convex and concave, 14..30 candidates);
- the same figures for pygad with the paper's settings (population 60, 600 generations,
  crossover 0.8, mutation probability 0.12 per gene, steady-state selection, elitism) on the
  same objective, in the same run.

Usage: ``python bench/capture.py [--repeats N] [--polygons N]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller import geometry  # noqa: E402
from controller.planning.capture import (
    PENALTY,
    CaptureParams,
    brute_force_capture,
    evaluate,
    make_problem,
    run_ga,
)

L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def sixty_node_problem():
    for spacing in np.linspace(0.09, 0.04, 200):
        prob = make_problem(L_SHAPE, 0.1, CaptureParams(spacing=float(spacing)))
        if len(prob.cand.points) >= 60:
            return prob
    raise RuntimeError("no spacing gives 60 nodes")


def random_polygons(count: int, rng: np.random.Generator):
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
        t0 = time.perf_counter()
        bf, _ = brute_force_capture(poly, 0.05, params)
        if bf <= -1e19:
            continue
        out.append((poly, params, bf, k, time.perf_counter() - t0))
        log(f"polygon {len(out)}: {k} nodes, optimum {bf:.4g} ({out[-1][4]:.1f} s brute force)")
    return out


def pygad_run(prob, seed: int) -> tuple[float, float]:
    import pygad

    k = len(prob.cand.points)
    p = prob.params

    def fitness(ga, solutions, idx):
        f, _ = evaluate(prob, np.asarray(solutions, dtype=bool).reshape(-1, k))
        return f.tolist()

    ga = pygad.GA(
        num_generations=p.generations,
        sol_per_pop=p.population,
        num_parents_mating=p.population // 2,
        num_genes=k,
        gene_space=[0, 1],
        gene_type=int,
        fitness_func=fitness,
        fitness_batch_size=p.population,
        crossover_probability=p.crossover,
        mutation_probability=p.mutation,
        keep_elitism=1,
        random_seed=seed,
        suppress_warnings=True,
    )
    t0 = time.perf_counter()
    ga.run()
    sec = time.perf_counter() - t0
    sol, fit, _ = ga.best_solution()
    return float(fit), sec


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--polygons", type=int, default=20)
    args = ap.parse_args()

    prob60 = sixty_node_problem()
    k60 = len(prob60.cand.points)
    rng = np.random.default_rng(0)
    pop = np.zeros((60, k60), bool)
    for r in range(60):
        pop[r, rng.choice(k60, int(rng.integers(3, 7)), replace=False)] = True
    rates = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        for _ in range(100):
            evaluate(prob60, pop)
        rates.append(6000 / (time.perf_counter() - t0))
    budget = []
    evals = 0
    for r in range(args.repeats):
        t0 = time.perf_counter()
        res = run_ga(prob60, np.random.default_rng(r))
        budget.append(time.perf_counter() - t0)
        evals = res.evaluations
    log(f"60-node budget: {statistics.median(budget):.3f} s for {evals} evaluations")

    polys = random_polygons(args.polygons, np.random.default_rng(2024))
    ours, theirs = [], []
    for i, (poly, params, bf, _, _) in enumerate(polys):
        prob = make_problem(poly, 0.05, params)
        t0 = time.perf_counter()
        res = run_ga(prob, np.random.default_rng(100 + i))
        ours.append((res.objective, time.perf_counter() - t0))
        f_pg, s_pg = pygad_run(prob, 100 + i)
        theirs.append((f_pg, s_pg))
        log(f"polygon {i + 1}: optimum {bf:.4g}, ours {res.objective:.4g}, pygad {f_pg:.4g}")

    def figures(results):
        gaps = [
            (bf - f) / bf if f > PENALTY / 2 else 1.0
            for (f, _), (_, _, bf, _, _) in zip(results, polys, strict=True)
        ]
        hits = sum(g <= 1e-9 for g in gaps)
        return {
            "hit_rate": hits / len(polys),
            "hits": hits,
            "median_gap": statistics.median(gaps),
            "max_gap": max(gaps),
            "median_seconds": statistics.median(s for _, s in results),
        }

    ours_fig, pygad_fig = figures(ours), figures(theirs)
    out = {
        "bench": "capture",
        "nodes_60": k60,
        "evaluations_per_s": statistics.median(rates),
        "paper_budget": {
            "evaluations": evals,
            "median_seconds": statistics.median(budget),
            "goal_seconds": 0.2,
            "goal_met": statistics.median(budget) < 0.2,
        },
        "polygons": len(polys),
        "nodes": [k for *_, k, _ in polys],
        "ours": ours_fig,
        "pygad": pygad_fig,
        "pygad_over_ours_seconds": pygad_fig["median_seconds"] / ours_fig["median_seconds"],
        "goal_hit_rate_met": ours_fig["hit_rate"] >= 0.95,
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
