"""Exact optima of the paper's GA problems by enumeration: the oracles the GA is measured
against (tests/unit/test_capture.py, test_capture_feasibility.py, bench/capture.py). Not part of
the planner: enumeration is exponential in the candidate nodes."""

from __future__ import annotations

import itertools

import numpy as np

from controller.planning.capture import (
    PENALTY,
    CaptureParams,
    FloatArray,
    evaluate,
    make_problem,
    push_objective,
)


def brute_force_capture(
    polygon: FloatArray,
    robot_radius: float,
    params: CaptureParams,
    sizes=range(3, 7),
    max_robots: int | None = None,
) -> tuple[float, np.ndarray]:
    """The exact optimum over node subsets of the given sizes (vectorized per chunk)."""
    prob = make_problem(polygon, robot_radius, params, max_robots=max_robots)
    k = len(prob.cand.points)
    best_f, best = PENALTY, np.zeros(k, bool)
    for s in sizes:
        if s > k:
            break
        combos = itertools.combinations(range(k), s)
        while True:
            chunk = np.fromiter(
                itertools.chain.from_iterable(itertools.islice(combos, 100_000)), dtype=np.int64
            ).reshape(-1, s)
            if len(chunk) == 0:
                break
            x = np.zeros((len(chunk), k), bool)
            np.put_along_axis(x, chunk, True, axis=1)
            f, _ = evaluate(prob, x)
            i = int(np.argmax(f))
            if f[i] > best_f:
                best_f, best = float(f[i]), x[i].copy()
    return best_f, best


def brute_force_push(
    polygon: FloatArray, robot_radius: float, direction: FloatArray, n: int, params: CaptureParams
) -> tuple[np.ndarray, float]:
    """Eq. 5's exact optimum over every string of exactly n nodes."""
    prob = make_problem(polygon, robot_radius, params)
    k = len(prob.cand.points)
    combos = np.array(list(itertools.combinations(range(k), n)), dtype=np.int64)
    x = np.zeros((len(combos), k), bool)
    np.put_along_axis(x, combos, True, axis=1)
    f, _ = push_objective(prob, direction, n, x)
    i = int(np.argmax(f))
    return np.flatnonzero(x[i]), float(f[i])
