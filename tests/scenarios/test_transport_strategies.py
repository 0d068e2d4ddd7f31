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

import math

import pytest

from controller.config import TRANSPORT_STRATEGIES
from controller.mission.factory import build_mission
from controller.runtime.dry_run import DryRun, judge
from tests.support.config import base_config_dict
from tests.support.transport_scenarios import CRATE, SCENARIOS, Scenario, scenario_config

# each local planner's closed-loop test: sa is the shipped default, so every transport scenario
# (tests/scenarios/test_transport_scenarios.py) runs it; the other two run here
CLOSED_LOOP = {
    "sa": "tests/scenarios/test_transport_scenarios.py::test_the_object_is_delivered",
    "downhill": "test_downhill_delivers_the_object",
    "serpentine": "test_serpentine_pushes_the_object_most_of_the_way_cleanly",
}


def test_every_strategy_runs_in_a_closed_loop_test():
    """A strategy added to the registry without a closed-loop test fails here; so does a new
    default that would leave ``sa`` out of the transport suite (its scenarios patch no
    strategy)."""
    assert set(CLOSED_LOOP) == set(TRANSPORT_STRATEGIES)
    assert base_config_dict(transport=True)["transport"]["strategy"] == "sa"
    assert all("strategy" not in sc.patch.get("transport", {}) for sc in SCENARIOS)
    assert all(name in globals() for name in list(CLOSED_LOOP.values())[1:])


def run(strategy: str, tmp_path, max_time: float | None = None) -> tuple[dict, object]:
    sc = Scenario(
        "open-floor-ideal",
        CRATE,
        (1.5, 2.5, 0.0),
        (5.5, 3.0, 0.0),
        patch={"transport": {"strategy": strategy}},
    )
    cfg = scenario_config(sc)
    out = tmp_path / f"{strategy}.mcap"
    res = DryRun(cfg, build_mission(cfg, "transport"), out, max_time=max_time).run()
    return res, cfg


@pytest.mark.e2e
def test_downhill_delivers_the_object(tmp_path):
    res, _ = run("downhill", tmp_path)
    assert judge(res) == []
    assert res["transported"] and res["status"] == "ok", res.get("failure")


@pytest.mark.e2e
def test_serpentine_pushes_the_object_most_of_the_way_cleanly(tmp_path):
    """Serpentine as published runs without breaking the hardware contract and carries the
    crate most of the way. Whether it ends inside the tolerance depends on the seed's Eq. 5
    draw (0.18 m on one, 1.09 m on another: it hovers short of the goal); the suite's figure is
    4 of 60 delivered (README, bench/transport_compare.py), so only the progress is asserted, at
    150 s of sim time (it gains about 1.5 cm/s here: 1.65 m left of 4.03 at 150 s, 1.09 at the
    200 s timeout; the last 50 s cost 20 s of CI time and prove nothing more)."""
    res, cfg = run("serpentine", tmp_path, max_time=150.0)
    assert judge(res) == []
    start = math.dist(cfg.object.start[:2], cfg.object.goal[:2])
    assert res["goal_error_m"] <= 0.5 * start, res.get("failure")
