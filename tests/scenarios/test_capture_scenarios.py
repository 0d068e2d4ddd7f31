"""The whole job on GA capture plans: GA plan, assignment on first sight, approach, close-in,
arrest, over zenoh with Kalman-filtered feedback, in the `ideal` world (fast) and in pybullet.
(tests/test_scenarios.py runs the approach on hand-made capture sets.)

Every scenario must arrest the object with no robot-robot overlap, at most 1 cm of robot-object
penetration and no obstacle contact.
"""

from __future__ import annotations

import pytest

from controller.mission.factory import build_mission
from controller.runtime.dry_run import DryRun, judge
from tests.support.capture_scenarios import SCENARIOS, scenario


def check(res: dict) -> None:
    assert res["arrested"], res
    assert res["done"] and not res["failed"]
    assert res["min_clearance_m"] is not None
    assert judge(res) == []
    assert res["arrival_spread_s"] is not None and res["arrival_spread_s"] >= 0
    assert res["missed_ticks"] == 0 and res["bad_payloads"] == 0


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_scenario_arrests_the_object(name, tmp_path):
    poly, motion, kinds, start, obstacles = SCENARIOS[name]
    cfg = scenario(poly, motion, kinds, start, obstacles, seed=sorted(SCENARIOS).index(name) + 1)
    res = DryRun(cfg, build_mission(cfg), tmp_path / "run.mcap", max_time=150).run()
    check(res)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["L-sine-default", "rect-line-fast", "T-evade-diff"])
def test_scenario_in_pybullet(name, tmp_path):
    poly, motion, kinds, start, obstacles = SCENARIOS[name]
    cfg = scenario(poly, motion, kinds, start, obstacles, seed=3, backend="pybullet")
    res = DryRun(cfg, build_mission(cfg), tmp_path / "run.mcap", max_time=150).run()
    check(res)
