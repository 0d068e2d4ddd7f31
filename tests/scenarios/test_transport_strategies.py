"""Every local planner in the closed loop (transport.strategy = sa, downhill, serpentine), over
the bus, judged from ground truth. ``sa`` (the default) is in every transport scenario; here
the same open floor with the other two.

- ``downhill`` (SA without uphill moves) must deliver as SA does: position and heading.
- ``serpentine`` (Sharma §4.3 as published) is judged on the paper's criterion: the object's
  CG ends within ``transport.tolerance`` of the goal (heading free, the method never aims
  for it), with a clean verdict. On ours it does not finish here (measured: it re-arranges
  near the goal until the time runs out; bench/transport_compare.py counts both criteria).
"""

from __future__ import annotations

import pytest

from controller.mission.factory import build_mission
from controller.runtime.dry_run import DryRun, judge
from tests.support.transport_scenarios import CRATE, Scenario, scenario_config


def run(strategy: str, tmp_path) -> tuple[dict, object]:
    sc = Scenario(
        "open-floor-ideal",
        CRATE,
        (1.5, 2.5, 0.0),
        (5.5, 3.0, 0.0),
        patch={"transport": {"strategy": strategy}},
    )
    cfg = scenario_config(sc)
    res = DryRun(cfg, build_mission(cfg, "transport"), tmp_path / f"{strategy}.mcap").run()
    return res, cfg


@pytest.mark.e2e
def test_downhill_delivers_the_object(tmp_path):
    res, _ = run("downhill", tmp_path)
    assert judge(res) == []
    assert res["transported"] and res["status"] == "ok", res.get("failure")


@pytest.mark.e2e
def test_serpentine_brings_the_cg_to_the_goal(tmp_path):
    res, cfg = run("serpentine", tmp_path)
    assert judge(res) == []
    assert res["goal_error_m"] <= cfg.transport.tolerance, res.get("failure")
