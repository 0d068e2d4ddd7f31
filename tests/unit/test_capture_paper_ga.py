"""capture.ga = "paper": Sharma's GA as published (binary strings, the −1e20 penalty, 60 × 600
evaluations, MATLAB ga operators), the baseline beside ours."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import parse_config
from controller.planning.capture import (
    PENALTY,
    CaptureParams,
    evaluate,
    ga_of,
    make_problem,
    plan_capture,
    run_ga,
    run_paper_ga,
)
from tests.support.config import base_config_dict, deep_update

L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)


def problem(ga: str = "paper"):
    p = CaptureParams(ga=ga)
    return make_problem(geometry.ensure_ccw(L_SHAPE), 0.1, p, max_robots=8), p


def test_paper_ga_spends_the_papers_budget_and_returns_a_feasible_string():
    prob, p = problem()
    res = run_paper_ga(prob, np.random.default_rng(0))
    assert 0.95 * 36_000 <= res.evaluations <= 36_000  # 60 × 600
    assert res.found
    f, v = evaluate(prob, res.best[None])
    assert v[0] == 0 and np.isclose(f[0], res.objective)
    assert all(b >= a for a, b in zip(res.history, res.history[1:], strict=False))  # elitism


def test_capture_ga_switch_picks_the_algorithm_and_defaults_to_ours():
    assert CaptureParams().ga == "ours"
    assert ga_of(CaptureParams()) is run_ga
    assert ga_of(CaptureParams(ga="paper")) is run_paper_ga
    cfg = parse_config(deep_update(base_config_dict(), {"capture": {"ga": "paper"}}))
    assert CaptureParams.from_config(cfg.capture).ga == "paper"


def test_paper_ga_is_seeded_and_runs_through_plan_capture():
    prob, p = problem()
    a = run_paper_ga(prob, np.random.default_rng(5))
    b = run_paper_ga(prob, np.random.default_rng(5))
    assert np.array_equal(a.best, b.best) and a.objective == b.objective
    plan = plan_capture(L_SHAPE, 0.1, p, np.random.default_rng(1), max_robots=8)
    assert plan.feasible and plan.objective > PENALTY
