"""Basic missions: ``GotoMission`` (drive to fixed points: staging, tests) and ``HoldMission``
(everyone stopped: bring-up checks)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.mission.tracking import RobotLimits, track_velocity
from controller.mission.types import FleetView, Intent, MissionOutput, Phase


@dataclass
class GotoMission:
    """Drive each robot to a fixed (x, y) target with a proportional law; done when all arrive."""

    targets: np.ndarray  # (N, 2)
    limits: RobotLimits
    gain: float = 1.0
    tolerance: float = 0.05

    def plan(self, view: FleetView) -> Intent:
        err = self.targets - view.poses[:, :2]
        arrived = np.linalg.norm(err, axis=1) < self.tolerance
        done = bool(np.all(arrived))
        phase = Phase.DONE if done else Phase.GOTO
        return Intent.of(self.gain * err, phase, hold=arrived, done=done)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        """No filter: staging and tests drive straight (the tracking law and the limits)."""
        cmds = track_velocity(view.poses, intent.command.velocities, self.limits)
        cmds[intent.command.hold] = 0.0
        cmds[view.stale | ~view.present] = 0.0
        return MissionOutput.of(cmds, intent)


@dataclass
class HoldMission:
    """Keep every robot stopped (bring-up checks: poses flow, estop works); never ends."""

    n: int

    def plan(self, view: FleetView) -> Intent:
        return Intent.of(np.zeros((self.n, 2)), Phase.HOLD, stop=True)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        return MissionOutput.of(np.zeros((self.n, 3)), intent)
