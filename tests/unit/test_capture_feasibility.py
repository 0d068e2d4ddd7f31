"""The capture planner never passes an infeasible plan off as a capture, works at fine spacings
and on large objects, plans with the fleet it has, and counts edges by shape (issue 15)."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pytest

from controller.cli import main
from controller.config import ConfigError, config_to_dict, load_config, parse_config
from controller.mission.job import CaptureJob, MissionError
from controller.planning.capture import (
    INFEASIBLE_RANK,
    CaptureParams,
    evaluate,
    make_problem,
    plan_capture,
    plan_for_fleet,
    rank_strings,
    run_ga,
)
from tests.support.capture_oracle import brute_force_capture
from tests.support.config import base_config_dict, deep_update, write_toml

L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)
PLUS = np.array(
    [(0.5, -1.5), (0.5, -0.5), (1.5, -0.5), (1.5, 0.5), (0.5, 0.5), (0.5, 1.5),
     (-0.5, 1.5), (-0.5, 0.5), (-1.5, 0.5), (-1.5, -0.5), (-0.5, -0.5), (-0.5, -1.5)]
)  # fmt: skip
PENTAGON = np.array([[np.cos(a), np.sin(a)] for a in 0.3 + np.arange(5) * 2 * np.pi / 5])


def config_with(tmp_path, patch: dict, robots: int | None = None):
    data = deep_update(base_config_dict(), patch)
    if robots is not None:
        data["robots"] = data["robots"][:robots]
    return write_toml(tmp_path / "fleet.toml", data)


def plan_json(path, capsys) -> tuple[int, dict]:
    status = main(["plan", "capture", "--config", str(path), "--json"])
    return status, json.loads(capsys.readouterr().out)


# --------------------------------------------------------------------------- 1, 7: outcomes


def test_robots_too_large_for_a_small_crate_is_refused_with_the_reason(tmp_path, capsys):
    small = (L_SHAPE * 0.15).tolist()
    path = config_with(tmp_path, {"object": {"polygon": small}})
    status, out = plan_json(path, capsys)
    assert status == 1
    assert out["feasible"] is False and out["form_closure"] is False
    # 2r + clearance, the clearance no less than approach.safety_margin (0.05)
    assert "robots too large" in out["reason"] and "0.25 m" in out["reason"]
    assert out["points"] == [] and out["robots_needed"] == 0 and out["objective"] == -1e20
    with pytest.raises(MissionError, match="robots too large"):
        CaptureJob(load_config(path))
    assert main(["run", "--config", str(path), "--out", str(tmp_path / "run.mcap")]) == 1
    assert "no feasible capture plan: robots too large" in capsys.readouterr().err


def test_spacing_violation_is_named_with_the_distances():
    plan = plan_capture(L_SHAPE * 0.2, 0.1, CaptureParams(), np.random.default_rng(7), 6)
    assert not plan.feasible and plan.violated == ["spacing"]
    assert "apart where 0.22 m" in plan.reason and "evaluations" in plan.reason


def test_paper_mode_mission_refuses_an_infeasible_plan_too(tmp_path):
    patch = {"object": {"polygon": (L_SHAPE * 0.15).tolist()}, "capture": {"closure": "paper"}}
    with pytest.raises(MissionError, match="no feasible capture plan"):
        CaptureJob(load_config(config_with(tmp_path, patch)))


def test_too_few_candidates_still_prints_its_json(tmp_path, capsys):
    tri = [[0.0, 0.0], [0.3, 0.0], [0.0, 0.3]]  # one node per edge at 0.5 m: 3 < 4
    path = config_with(tmp_path, {"object": {"polygon": tri}, "capture": {"spacing": 0.5}})
    status, out = plan_json(path, capsys)
    assert status == 1 and out["feasible"] is False and out["violated"] == ["robots"]
    assert "capture.spacing" in out["reason"] and "needs 4 robots" in out["reason"]


# --------------------------------------------------------------------------- 2: ranking


def test_infeasible_strings_are_ranked_by_their_violations():
    assert -1e30 - 1 == -1e30  # why the old key tied every infeasible string
    f = np.array([-1e20, -1e20, 2.0, -1e20])
    v = np.array([3, 1, 0, 2])
    key = rank_strings(f, v)
    assert list(np.argsort(-key)) == [2, 1, 3, 0]
    assert key[1] == INFEASIBLE_RANK
    # with no feasible string the elite is the least violating one
    assert int(np.argmax(rank_strings(f[[0, 1, 3]], v[[0, 1, 3]]))) == 1


# --------------------------------------------------------------------------- 3, 4: scale


def test_large_object_fine_spacing_stays_small_and_never_builds_a_pair_table():
    square = np.array([[0, 0], [20.0, 0], [20.0, 20.0], [0, 20.0]])
    params = CaptureParams(spacing=0.04, generations=15)  # K = 2000
    tracemalloc.start()
    try:
        prob = make_problem(square, 0.1, params, max_robots=6)
        plan = plan_capture(square, 0.1, params, np.random.default_rng(0), max_robots=6)
        x = np.zeros((60, len(prob.cand.points)), bool)
        x[:, :: len(prob.cand.points) // 5] = True
        _, start_peak = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        evaluate(prob, x)
        _, eval_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(prob.cand.points) == 2000 and len(plan.candidates) == 2000
    # a (K, K) float table is 32 MB at K = 2000 (the old overlap product, BLAS-threaded)
    assert start_peak < 30e6 and eval_peak < 2e6
    assert plan.feasible and plan.robots_needed <= 6


def test_spacing_past_the_node_budget_names_capture_spacing(tmp_path, capsys):
    square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]
    patch = {"object": {"polygon": square, "start": [1.0, 1.0, 0.0], "goal": [1.5, 1.5, 0.0]}}
    cfg = deep_update(base_config_dict(), {**patch, "capture": {"spacing": 0.0001}})
    with pytest.raises(ConfigError) as err:
        parse_config(cfg)
    assert err.value.path == "capture.spacing" and "use capture.spacing >=" in err.value.message
    plan = plan_capture(
        np.array(square), 0.1, CaptureParams(spacing=0.0001), np.random.default_rng(0), 6
    )
    assert not plan.feasible and plan.reason.startswith("capture.spacing:")
    assert main(["check", "--config", str(write_toml(tmp_path / "b.toml", cfg))]) == 2
    assert "capture.spacing" in capsys.readouterr().err


# --------------------------------------------------------------------------- 5: the fleet


def test_three_robots_plan_a_three_robot_capture_when_one_exists():
    params = CaptureParams(spacing=0.2, closure="paper")
    best3, _ = brute_force_capture(PENTAGON, 0.05, params, sizes=(3,))
    best_any, any_bits = brute_force_capture(PENTAGON, 0.05, params)
    assert any_bits.sum() == 4 and best_any > best3 > 0  # unlimited, the optimum takes four
    plan = plan_capture(PENTAGON, 0.05, params, np.random.default_rng(0), max_robots=3)
    assert plan.feasible and plan.robots_needed == 3
    assert plan.objective == pytest.approx(best3)


def test_a_twelve_robot_fleet_beats_every_eight_robot_set_on_a_plus():
    params = CaptureParams(spacing=0.25, k=0.0)
    prob = make_problem(PLUS, 0.1, params)
    # f <= (sum of the 8 largest |m| an edge offers) / epsilon for any 8 robots (k = 0)
    best_per_edge = [np.abs(prob.moments[prob.cand.edges == e]).max() for e in range(12)]
    bound8 = sum(sorted(best_per_edge)[-8:]) / params.epsilon
    plan = plan_capture(PLUS, 0.1, params, np.random.default_rng(0), max_robots=12)
    assert plan.feasible and plan.form_closure and plan.robots_needed > 8
    assert plan.objective > bound8 + 1e-9


# --------------------------------------------------------------------------- 6: vertex lists


def test_collinear_and_duplicate_vertices_are_merged_and_reported(tmp_path, capsys):
    rect = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    noisy = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 1.0], [1.0, 1.0], [0.0, 1.0]]
    plain = load_config(config_with(tmp_path, {"object": {"polygon": rect}}))
    path = config_with(tmp_path, {"object": {"polygon": noisy}})
    merged = load_config(path)
    assert merged.object.polygon == plain.object.polygon and plain.notes == ()
    assert "merged 1 duplicate and 2 collinear" in merged.notes[0]
    data = config_to_dict(merged)  # as logged: loads again, notes are no config key
    data.pop("source")
    assert parse_config(data).object.polygon == merged.object.polygon
    assert main(["check", "--config", str(path), "--json"]) == 0
    assert "merged" in json.loads(capsys.readouterr().out)["notes"][0]
    assert main(["check", "--config", str(path)]) == 0
    assert "note: object.polygon: merged" in capsys.readouterr().out
    a = plan_capture(plain.object_polygon(), 0.1, CaptureParams(), np.random.default_rng(0), 6)
    b = plan_capture(merged.object_polygon(), 0.1, CaptureParams(), np.random.default_rng(0), 6)
    assert a.robots_needed == b.robots_needed == 4 and a.objective == b.objective


# --------------------------------------------------------------------------- the GA itself


def test_ga_best_never_gets_worse_and_stays_inside_the_fleet():
    prob = make_problem(L_SHAPE, 0.1, CaptureParams(generations=120), max_robots=5)
    res = run_ga(prob, np.random.default_rng(3))
    assert res.history == sorted(res.history) and res.found
    assert 4 <= res.best.sum() <= 5 and res.evaluations <= 60 * 120


def test_a_capture_needing_more_robots_than_the_fleet_says_how_many():
    # axis-aligned normals: three pushes never span the plane, four do
    params = CaptureParams(closure="paper")
    plan = plan_capture(L_SHAPE, 0.1, params, np.random.default_rng(0), max_robots=3)
    assert not plan.feasible and plan.violated == ["fleet"]
    assert "needs 4 robots" in plan.reason and "the fleet has 3" in plan.reason


def test_fleet_plans_keep_the_approach_safety_margin_between_robots(tmp_path):
    # the U's notch holds two robots 0.224 m apart (2r + capture.clearance = 0.22) but the
    # approach's safety filter keeps them 2r + approach.safety_margin = 0.25 m apart
    u = [
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 0.8],
        [0.7, 0.8],
        [0.7, 0.3],
        [0.3, 0.3],
        [0.3, 0.8],
        [0.0, 0.8],
    ]
    cfg = load_config(config_with(tmp_path, {"object": {"polygon": u}, "capture": {"seed": 1}}))
    free = plan_capture(cfg.object_polygon(), 0.1, CaptureParams(), np.random.default_rng(1), 6)
    plan = plan_for_fleet(cfg, np.random.default_rng(1))
    gap = 2 * cfg.max_robot_radius + cfg.approach.safety_margin

    def closest(p) -> float:
        c = p.points + cfg.max_robot_radius * p.push_normals
        return float(
            np.linalg.norm(c[:, None] - c[None], axis=-1)[np.triu_indices(len(c), 1)].min()
        )

    assert free.feasible and closest(free) < gap  # the optimum on capture.clearance alone
    assert plan.feasible and closest(plan) >= gap - 1e-9
