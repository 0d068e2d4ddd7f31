"""How long a MAVLink rover drives on by itself once our stream stops: the vehicle's own
timeouts, read on connect, judged against ``max_vehicle_timeout``. Pure: parameters in, a
verdict out (the driver reads the parameters and warns, or refuses under ``--strict``).

PX4: ``COM_OF_LOSS_T`` s after the last OFFBOARD setpoint it switches to its loss action.

ArduRover (ArduPilot source, Rover/):

- GUIDED (mode_guided.cpp): a speed + turn-rate or speed + heading target is dropped, and the
  rover stopped, when no new target came for ``GUID_TIMEOUT`` s (``get_timeout_ms``, at least
  0.1 s; parameter of newer firmware, default 3 s); firmware without it stops after a fixed 3 s
  ("target not received last 3secs, stopping").
- GCS failsafe (Rover.cpp ``gcs_failsafe_check``, failsafe.cpp ``failsafe_trigger``): only with
  ``FS_GCS_ENABLE`` != 0 and once a heartbeat from the GCS system id (``SYSID_MYGCS``) was seen;
  the failsafe condition starts when none came for ``FS_GCS_TIMEOUT`` s (newer firmware; older:
  a fixed 2 s) and ``FS_ACTION`` is taken when it has lasted ``FS_TIMEOUT`` s more. FS_ACTION 2
  (Hold) stops the rover; 1 and 3 (RTL, SmartRTL or RTL) drive it home across the lab, 4
  SmartRTL first, 0 does nothing. Not in HOLD (unless FS_OPTIONS bit 0) nor in RTL.

So an ArduRover whose driver dies keeps its last target for min(GUIDED timeout, GCS lost +
FS_TIMEOUT) s (the second only with a Hold action). Unsafe (warned; ``--strict`` refuses): a
parameter it does not answer, no GCS failsafe, a failsafe action that drives or does nothing,
or that time above ``max_vehicle_timeout``. Worth a warning only: the GCS condition plus
FS_TIMEOUT shorter than three periods of our heartbeat (one lost heartbeat may trip it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from drivers.mavlink import convert as mc

HEARTBEAT_MARGIN = 3.0  # our heartbeat periods the GCS failsafe must span

#: what the driver asks an ArduRover on connect: needed, then read if the firmware has them
ROVER_REQUIRED = (mc.ROVER_FS_GCS_ENABLE, mc.ROVER_FS_TIMEOUT, mc.ROVER_FS_ACTION)
ROVER_OPTIONAL = (mc.ROVER_FS_GCS_TIMEOUT, mc.ROVER_GUID_TIMEOUT)


@dataclass(frozen=True)
class Verdict:
    """``stop_after``: s the vehicle keeps its last setpoint once our stream and heartbeats stop
    (None: unknown); ``problems``: unsafe (a warning, refused under ``--strict``); ``notes``:
    warnings only."""

    stop_after: float | None
    problems: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


def assess_px4(loss_timeout: float | None, limit: float) -> Verdict:
    """PX4's ``COM_OF_LOSS_T`` (s, None: unanswered) against ``limit`` (s)."""
    name = mc.PX4_OFFBOARD_LOSS_PARAM
    if loss_timeout is None:
        return Verdict(None, (f"did not answer a read of {name}: its offboard timeout is unknown",))
    if loss_timeout > limit + 1e-6:
        return Verdict(
            loss_timeout,
            (
                f"has {name} = {loss_timeout:g} s, longer than max_vehicle_timeout = {limit:g} s:"
                f" if this process dies the rover drives on for {loss_timeout:g} s; set {name} <= "
                f"{limit:g} on the vehicle",
            ),
        )
    return Verdict(loss_timeout)


def _guided_timeout(params: Mapping[str, float]) -> tuple[float, str]:
    value = params.get(mc.ROVER_GUID_TIMEOUT)
    if value is None:
        return mc.ROVER_GUIDED_TIMEOUT_FIXED, "fixed, no GUID_TIMEOUT in this firmware"
    return max(float(value), 0.1), f"GUID_TIMEOUT = {value:g} s"


def _gcs_failsafe(params: Mapping[str, float], heartbeat_period: float) -> tuple[float, list, list]:
    """(s until the GCS failsafe holds the rover or inf, problems, notes)."""
    enable = params[mc.ROVER_FS_GCS_ENABLE]
    action = int(params[mc.ROVER_FS_ACTION])
    fs_timeout = float(params[mc.ROVER_FS_TIMEOUT])
    gap = params.get(mc.ROVER_FS_GCS_TIMEOUT)
    gap_text = "2 s fixed" if gap is None else f"FS_GCS_TIMEOUT = {gap:g} s"
    gap = mc.ROVER_GCS_LOST_FIXED if gap is None else float(gap)
    problems: list[str] = []
    notes: list[str] = []
    if int(enable) == 0:
        problems.append(
            "has FS_GCS_ENABLE = 0 (no GCS failsafe): a rover whose link or driver is lost "
            "stays armed in GUIDED; set FS_GCS_ENABLE = 1 and FS_ACTION = 2 (Hold)"
        )
        return math.inf, problems, notes
    if action != mc.ROVER_FS_ACTION_HOLD:
        what = mc.ROVER_FS_ACTIONS.get(action, f"unknown action {action}")
        drives = "drives it across the lab" if "RTL" in what else "does not stop it"
        problems.append(
            f"has FS_ACTION = {action} ({what}): its GCS failsafe {drives}; set FS_ACTION = 2 "
            "(Hold)"
        )
    least = HEARTBEAT_MARGIN * heartbeat_period
    if gap + fs_timeout < least - 1e-9:
        notes.append(
            f"its GCS failsafe acts {gap + fs_timeout:g} s after our last heartbeat ({gap_text} + "
            f"FS_TIMEOUT = {fs_timeout:g} s), under {HEARTBEAT_MARGIN:g} periods of our "
            f"{1.0 / heartbeat_period:g} Hz heartbeat: one lost heartbeat may trip it (raise "
            "mavlink.heartbeat_hz)"
        )
    if action != mc.ROVER_FS_ACTION_HOLD:
        return math.inf, problems, notes
    return gap + fs_timeout, problems, notes


def assess_ardurover(params: Mapping[str, float], limit: float, heartbeat_period: float) -> Verdict:
    """An ArduRover's failsafe parameters as read (names of :data:`ROVER_REQUIRED` and
    :data:`ROVER_OPTIONAL`; a missing name was not answered) against ``limit`` (s,
    ``max_vehicle_timeout``) and our heartbeat period (s)."""
    missing = [n for n in ROVER_REQUIRED if params.get(n) is None]
    guided, guided_text = _guided_timeout(params)
    if missing:
        problem = (
            f"did not answer a read of {', '.join(missing)}: its GCS failsafe is unknown "
            f"(the GUIDED timeout alone stops it after {guided:g} s, {guided_text})"
        )
        return Verdict(None, (problem,))
    held, problems, notes = _gcs_failsafe(params, heartbeat_period)
    stop_after = min(guided, held)
    if stop_after > limit + 1e-6:
        failsafe = "" if math.isinf(held) else f", its GCS failsafe holds it after {held:g} s"
        problems.append(
            f"keeps its last target for {stop_after:g} s if this process dies (GUIDED timeout "
            f"{guided:g} s, {guided_text}{failsafe}), longer than max_vehicle_timeout = "
            f"{limit:g} s; set GUID_TIMEOUT <= {limit:g} on the vehicle (firmware with it) or "
            "raise max_vehicle_timeout"
        )
    return Verdict(stop_after, tuple(problems), tuple(notes))
