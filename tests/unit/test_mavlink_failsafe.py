"""How long a MAVLink rover drives on by itself (drivers/mavlink/failsafe.py), against the
ArduPilot source's arithmetic: GUIDED drops a target after GUID_TIMEOUT (fixed 3 s without the
parameter); the GCS failsafe acts FS_GCS_TIMEOUT (fixed 2 s without it) + FS_TIMEOUT after the
last GCS heartbeat, and only FS_ACTION = 2 (Hold) stops the rover."""

from __future__ import annotations

import math

import pytest

from drivers.mavlink.failsafe import assess_ardurover, assess_px4

SAFE = {"FS_GCS_ENABLE": 1, "FS_TIMEOUT": 1.5, "FS_ACTION": 2, "GUID_TIMEOUT": 0.5}


def test_a_short_guided_timeout_with_a_holding_failsafe_is_safe():
    v = assess_ardurover(SAFE, limit=1.0, heartbeat_period=1.0)
    assert v.stop_after == pytest.approx(0.5) and v.problems == () and v.notes == ()


def test_ardurover_defaults_are_unsafe_twice():
    """Firmware defaults (FS_GCS_ENABLE 0, FS_TIMEOUT 1.5, FS_ACTION 2) and no GUID_TIMEOUT
    parameter: no GCS failsafe, and the fixed 3 s GUIDED timeout is over a 1 s limit."""
    v = assess_ardurover({"FS_GCS_ENABLE": 0, "FS_TIMEOUT": 1.5, "FS_ACTION": 2}, 1.0, 1.0)
    assert v.stop_after == pytest.approx(3.0)
    assert len(v.problems) == 2
    assert "FS_GCS_ENABLE = 0" in v.problems[0]
    assert "3 s" in v.problems[1] and "no GUID_TIMEOUT" in v.problems[1]
    assert "max_vehicle_timeout = 1 s" in v.problems[1]


@pytest.mark.parametrize(("action", "word"), [(1, "RTL"), (3, "SmartRTL or RTL"), (0, "nothing")])
def test_a_failsafe_action_that_does_not_hold_is_a_problem(action, word):
    v = assess_ardurover({**SAFE, "FS_ACTION": action}, limit=1.0, heartbeat_period=1.0)
    assert v.stop_after == pytest.approx(0.5)  # the GUIDED timeout still stops the target
    assert len(v.problems) == 1 and f"FS_ACTION = {action} ({word})" in v.problems[0]


def test_the_gcs_failsafe_stops_first_when_the_guided_timeout_is_long():
    params = {**SAFE, "GUID_TIMEOUT": 5.0, "FS_GCS_TIMEOUT": 2.0, "FS_TIMEOUT": 1.0}
    v = assess_ardurover(params, limit=4.0, heartbeat_period=0.5)
    assert v.stop_after == pytest.approx(3.0) and v.problems == ()
    v = assess_ardurover(params, limit=1.0, heartbeat_period=0.5)
    assert v.stop_after == pytest.approx(3.0)
    assert "GCS failsafe holds it after 3 s" in v.problems[0]


def test_an_unanswered_failsafe_parameter_is_unknown():
    v = assess_ardurover({"FS_GCS_ENABLE": 1, "FS_ACTION": 2}, limit=1.0, heartbeat_period=1.0)
    assert v.stop_after is None
    assert "did not answer a read of FS_TIMEOUT" in v.problems[0]


@pytest.mark.parametrize(("period", "noted"), [(1.0, False), (2.0, True)])
def test_a_failsafe_shorter_than_three_heartbeats_is_noted(period, noted):
    """2 s (fixed) + FS_TIMEOUT 1 s = 3 s after the last heartbeat: three 1 s periods are fine,
    at one heartbeat every 2 s one lost heartbeat trips it (a note, not a refusal)."""
    v = assess_ardurover({**SAFE, "FS_TIMEOUT": 1.0}, limit=1.0, heartbeat_period=period)
    assert bool(v.notes) is noted and v.problems == ()


def test_px4_offboard_loss():
    assert assess_px4(0.5, 1.0).problems == ()
    assert "COM_OF_LOSS_T = 5 s" in assess_px4(5.0, 1.0).problems[0]
    assert assess_px4(None, 1.0).stop_after is None
    assert math.isclose(assess_px4(5.0, 1.0).stop_after, 5.0)
