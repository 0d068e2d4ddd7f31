"""The one verdict (runtime/dry_run.judge): each rule of the hardware contract, alone."""

from __future__ import annotations

import pytest

from controller.runtime.dry_run import RULES, judge

CLEAN = {
    "min_clearance_m": 0.05,
    "max_object_penetration_m": 0.0,
    "obstacle_contacts": [],
    "hold_displacement_m": 0.01,
    "object_min_clearance_m": 0.3,
}


def test_a_clean_run_passes():
    assert judge(CLEAN) == []


@pytest.mark.parametrize(
    "key, value, reason",
    [
        ("min_clearance_m", -1e-5, "collision"),
        ("max_object_penetration_m", 0.02, "penetration"),
        ("obstacle_contacts", ["r3"], "obstacle_contact"),
        ("hold_displacement_m", RULES.max_hold_displacement_m + 0.01, "escaped"),
        ("object_min_clearance_m", -0.5, "object_collision"),  # through a wall, out of the room
    ],
)
def test_each_rule_fails_its_run_and_names_itself(key, value, reason):
    out = judge({**CLEAN, key: value})
    assert [f["reason"] for f in out] == [reason] and out[0]["detail"]


def test_unknown_figures_are_not_failures():
    assert judge({k: None for k in CLEAN} | {"obstacle_contacts": []}) == []
