"""Missions: the pure per-tick decision of what every robot does.

A mission takes a ``FleetView`` (estimates as arrays, time passed in) and returns body-frame
commands for every robot. ``GotoMission`` drives robots to fixed poses (staging, tests);
the capture-and-transport mission lives in ``controller.capture_mission``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller import geometry


@dataclass(frozen=True)
class RobotLimits:
    """Per-robot limits as arrays (N,): holonomic flags, m/s, rad/s, m/s^2."""

    holonomic: np.ndarray
    max_speed: np.ndarray
    max_yaw_rate: np.ndarray
    max_accel: np.ndarray

    @classmethod
    def from_config(cls, robots) -> RobotLimits:
        return cls(
            holonomic=np.array([r.kind == "omni" for r in robots]),
            max_speed=np.array([r.max_speed for r in robots]),
            max_yaw_rate=np.array([r.max_yaw_rate for r in robots]),
            max_accel=np.array([r.max_accel for r in robots]),
        )


def world_to_body(theta: np.ndarray, v_world: np.ndarray) -> np.ndarray:
    """Rotate world-frame velocities (N, 2) into each robot's body frame."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack(
        [c * v_world[:, 0] + s * v_world[:, 1], -s * v_world[:, 0] + c * v_world[:, 1]], 1
    )


def track_velocity(
    poses: np.ndarray,
    v_world: np.ndarray,
    limits: RobotLimits,
    heading_gain: float = 3.0,
    desired_heading: np.ndarray | None = None,
) -> np.ndarray:
    """Body-frame commands (N, 3) that realise desired world velocities (N, 2).

    Omni robots translate directly (and turn toward ``desired_heading`` if given). Differential
    robots turn toward the velocity's direction and drive forward with the component of the
    desired velocity along their heading (never backwards through a turn), under their limits.
    """
    n = len(poses)
    th = poses[:, 2]
    body = world_to_body(th, v_world)
    cmds = np.zeros((n, 3))
    speed = np.linalg.norm(v_world, axis=1)
    omni = limits.holonomic
    cmds[omni, 0:2] = body[omni]
    if desired_heading is not None:
        err = geometry.wrap_angle(desired_heading - th)
        cmds[omni, 2] = heading_gain * err[omni]
    diff = ~omni
    if np.any(diff):
        heading = np.arctan2(v_world[:, 1], v_world[:, 0])
        err = geometry.wrap_angle(heading - th)
        moving = speed > 1e-6
        wz = np.where(moving, heading_gain * err, 0.0)
        fwd = np.where(moving, np.maximum(body[:, 0], 0.0) * np.clip(np.cos(err), 0.0, 1.0), 0.0)
        cmds[diff, 0] = fwd[diff]
        cmds[diff, 2] = wz[diff]
    # limits
    lin = np.linalg.norm(cmds[:, :2], axis=1)
    k = np.where(lin > limits.max_speed, limits.max_speed / np.maximum(lin, 1e-12), 1.0)
    cmds[:, :2] *= k[:, None]
    cmds[:, 2] = np.clip(cmds[:, 2], -limits.max_yaw_rate, limits.max_yaw_rate)
    return cmds


# rad a differential robot keeps driving toward the end of its axis it chose (forward or
# backward) beyond the point where the other end is nearer: without it, a desired velocity
# near 90 degrees off the axis flips the choice tick by tick, the heading error jumps between
# about +90 and -90 degrees and the robot is commanded full yaw rate one way, then the other
# (measured in a real-time lab run: wz +2 / -2 rad/s tick after tick, the robot dithering and
# its filter rejecting its poses for a minute)
REVERSE_HYSTERESIS = np.radians(30.0)


def track_reversible(
    poses: np.ndarray,
    v_world: np.ndarray,
    limits: RobotLimits,
    heading_gain: float = 4.0,
    turn_deadband: float = 0.03,
    aim: np.ndarray | None = None,
) -> np.ndarray:
    """Like :func:`controller.mission.track_velocity`, but a differential robot may drive
    backwards: it aligns its axis (either way) with the desired velocity and drives with the
    signed component along its heading. Station keeping then needs no U-turns. Each tick on
    its own: the nearer end of the axis (see :func:`track_reversible_ends` for the choice
    kept from one tick to the next).

    With ``aim`` (N, 2), the safety filter's free solution, ``v_world`` is already along each
    differential robot's axis (the filter's axis rows): the robot drives exactly that (the
    velocity the barriers were kept for) and turns toward ``aim``."""
    return track_reversible_ends(poses, v_world, limits, heading_gain, turn_deadband, aim)[0]


def track_reversible_ends(
    poses: np.ndarray,
    v_world: np.ndarray,
    limits: RobotLimits,
    heading_gain: float = 4.0,
    turn_deadband: float = 0.03,
    aim: np.ndarray | None = None,
    backward: np.ndarray | None = None,
    keep: float = REVERSE_HYSTERESIS,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`track_reversible` with the end of the axis each differential robot drives toward
    kept from the last tick: ``backward`` (N,) the last tick's choice (None: none yet), kept
    until the other end is nearer to the desired direction by more than ``keep`` rad; a robot
    below the turn deadband keeps it. Returns the commands (N, 3) and this tick's choice (N,)
    (False for holonomic robots)."""
    cmds = track_velocity(poses, v_world, limits)
    diff = ~limits.holonomic
    ends = np.zeros(len(poses), bool)
    if not np.any(diff):
        return cmds, ends
    th = poses[diff, 2]
    v = v_world[diff]
    toward = v if aim is None else np.asarray(aim, float)[diff]
    speed = np.linalg.norm(toward, axis=1)
    body = world_to_body(th, toward)
    a = np.arctan2(body[:, 1], body[:, 0])  # the desired direction from the forward end
    back = np.abs(a) > np.pi / 2  # the nearer end
    # below ``turn_deadband`` m/s a differential robot does not turn (only drives along its
    # axis): turning toward a few mm/s of noise makes it spin in place against its contact
    moving = speed > turn_deadband
    if backward is not None:
        prev = np.asarray(backward, bool)[diff]
        off = np.where(prev, np.pi - np.abs(a), np.abs(a))  # from the end chosen last tick
        back = np.where(~moving | (off < np.pi / 2 + keep), prev, back)
    err = np.where(back, geometry.wrap_angle(a - np.pi), a)
    wz = np.where(moving, heading_gain * err, 0.0)
    if aim is None:
        fwd = body[:, 0] * np.abs(np.cos(err))
    else:
        fwd = world_to_body(th, v)[:, 0]
    fwd = np.clip(fwd, -limits.max_speed[diff], limits.max_speed[diff])
    cmds[diff, 0] = fwd
    cmds[diff, 1] = 0.0
    cmds[diff, 2] = np.clip(wz, -limits.max_yaw_rate[diff], limits.max_yaw_rate[diff])
    ends[diff] = back
    return cmds, ends
