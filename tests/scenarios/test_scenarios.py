"""Seeded capture scenarios through the real lockstep dry run (zenoh, driver agents, estimator).

Every scenario must arrest the moving object with no robot-robot overlap, at most 1 cm of
object penetration and no obstacle contact. The capture sets are hand-made (tests/capture_sets);
the GA capture planner feeds the same ``CaptureMission`` in the full job.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from controller import geometry
from controller.mission.capture import CaptureMission
from controller.runtime.dry_run import DryRun, judge
from tests.support.capture_sets import l_shape_points, nearest_assignment, rectangle_points
from tests.support.config import make_config

L_POLY = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]]
RECT_POLY = [[0.0, 0.0], [0.8, 0.0], [0.8, 0.5], [0.0, 0.5]]
T_POLY = [[0.0, 0.0], [0.4, 0.0], [0.4, 0.6], [0.8, 0.6], [0.8, 0.9], [-0.4, 0.9], [-0.4, 0.6],
          [0.0, 0.6]]  # fmt: skip


def t_points():
    pts = np.array([[0.3, 0.0], [0.8, 0.75], [-0.2, 0.9], [-0.4, 0.7], [0.4, 0.35]])
    nrm = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [1.0, 0.0]])
    return pts, nrm


SHAPES = {
    "L": (L_POLY, l_shape_points),
    "rect": (RECT_POLY, lambda: rectangle_points(0.8, 0.5)),
    "T": (T_POLY, t_points),
}


@dataclass
class Scenario:
    name: str
    shape: str
    motion: dict
    start: list
    robots: list  # (kind, x, y, theta)
    seed: int = 1
    obstacles: list = field(default_factory=list)
    backend: str = "ideal"
    max_time: float = 60.0


def robots(kind: str | list[str], starts: list[tuple[float, float, float]]) -> list:
    kinds = [kind] * len(starts) if isinstance(kind, str) else kind
    return [(k, *s) for k, s in zip(kinds, starts, strict=True)]


FOUR = [(1.0, 1.0, 0.0), (4.0, 1.0, 1.57), (1.0, 5.0, 0.0), (4.5, 5.0, 3.14)]
FIVE = FOUR + [(2.5, 6.5, -1.57)]
MIXED = ["omni", "diff", "diff", "omni"]

SCENARIOS = [
    Scenario("L_sine_mixed", "L", {"kind": "sine", "speed": 0.06}, [2.0, 3.0, 0.0],
             robots(MIXED, FOUR)),
    Scenario("L_line_half_speed_omni", "L", {"kind": "line", "speed": 0.2, "heading": 0.0},
             [2.0, 3.0, 0.0], robots("omni", FOUR), seed=2),
    Scenario("L_line_half_speed_diff", "L", {"kind": "line", "speed": 0.2, "heading": 0.0},
             [2.0, 3.0, 0.0], robots("diff", FOUR), seed=3),
    Scenario("rect_line_diag_omni", "rect", {"kind": "line", "speed": 0.1, "heading": 0.6},
             [2.5, 2.5, 0.3], robots("omni", FOUR), seed=4),
    Scenario("rect_sine_diff", "rect", {"kind": "sine", "speed": 0.15, "amplitude": 0.5},
             [2.5, 3.0, 0.0], robots("diff", FOUR), seed=5),
    Scenario("rect_evade_omni", "rect", {"kind": "evade", "speed": 0.05, "max_speed": 0.2},
             [3.0, 3.0, 0.0], robots("omni", FOUR), seed=6),
    Scenario("L_evade_mixed", "L", {"kind": "evade", "speed": 0.05, "max_speed": 0.2},
             [2.5, 3.0, 0.0], robots(MIXED, FOUR), seed=7),
    Scenario("T_sine_omni", "T", {"kind": "sine", "speed": 0.1}, [2.5, 3.0, 0.0],
             robots("omni", FIVE), seed=8),
    Scenario("T_line_mixed", "T", {"kind": "line", "speed": 0.15, "heading": 0.3},
             [2.5, 2.8, 0.0], robots(MIXED + ["diff"], FIVE), seed=9),
    Scenario("rect_turned_line_diff", "rect", {"kind": "line", "speed": 0.1, "heading": -0.4},
             [2.5, 4.0, 1.0], robots("diff", FOUR), seed=10),
    Scenario("L_obstacle_in_the_way", "L", {"kind": "line", "speed": 0.05, "heading": 0.0},
             [5.8, 7.0, 0.0], robots(MIXED, [(5.0, 3.8, 1.57), (5.8, 3.8, 1.57),
                                              (7.0, 3.8, 1.57), (7.8, 3.8, 1.57)]),
             seed=11, obstacles=[[[5.6, 5.0], [7.2, 5.0], [7.2, 5.8], [5.6, 5.8]]]),
]  # fmt: skip

SLOW = [
    Scenario("pybullet_L_sine_mixed", "L", {"kind": "sine", "speed": 0.06}, [2.0, 3.0, 0.0],
             robots(MIXED, FOUR), backend="pybullet"),
    Scenario("pybullet_rect_line_omni", "rect", {"kind": "line", "speed": 0.15, "heading": 0.6},
             [2.5, 2.5, 0.3], robots("omni", FOUR), seed=12, backend="pybullet"),
]  # fmt: skip


def robot_dicts(sc: Scenario) -> list[dict]:
    return [
        {
            "id": f"r{i + 1}",
            "kind": k,
            "radius": 0.1,
            "max_speed": 0.4,
            "max_yaw_rate": 2.0,
            "max_force": 6.0,
            "driver": "sim",
            "start": [x, y, th],
        }
        for i, (k, x, y, th) in enumerate(sc.robots)
    ]


def run_scenario(sc: Scenario, path) -> tuple[dict, CaptureMission]:
    poly, pts_fn = SHAPES[sc.shape]
    cfg = make_config(
        {
            "sim": {"backend": sc.backend, "seed": sc.seed},
            "object": {"polygon": poly, "start": sc.start, "motion": sc.motion},
            "obstacles": [{"polygon": p} for p in sc.obstacles],
            "robots": robot_dicts(sc),
        }
    )
    pts, nrm = pts_fn()
    pw = geometry.transform(pts, cfg.object.start)
    assignment = nearest_assignment(pw, np.array([r.start[:2] for r in cfg.robots]))
    mission = CaptureMission(pts, nrm, assignment, cfg, np.random.default_rng(sc.seed))
    res = DryRun(cfg, mission, path, max_time=sc.max_time).run()
    return res, mission


def check(res: dict) -> None:
    assert res["arrested"], res
    assert res["mission"]["arrival_spread_s"] is not None
    assert judge(res) == []


@pytest.mark.parametrize("sc", SCENARIOS, ids=[s.name for s in SCENARIOS])
def test_scenario_arrests(sc, tmp_path):
    res, _ = run_scenario(sc, tmp_path / f"{sc.name}.mcap")
    check(res)


@pytest.mark.slow
@pytest.mark.parametrize("sc", SLOW, ids=[s.name for s in SLOW])
def test_scenario_pybullet(sc, tmp_path):
    res, _ = run_scenario(sc, tmp_path / f"{sc.name}.mcap")
    check(res)
