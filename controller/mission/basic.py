"""Basic missions: ``GotoMission`` (drive to fixed points: staging, tests) and ``HoldMission``
(everyone stopped: bring-up checks)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.mission.tracking import RobotLimits, track_velocity
from controller.mission.types import FleetView, MissionOutput


@dataclass
class GotoMission:
    """Drive each robot to a fixed (x, y) target with a proportional law; done when all arrive."""

    targets: np.ndarray  # (N, 2)
    limits: RobotLimits
    gain: float = 1.0
    tolerance: float = 0.05

    def step(self, view: FleetView) -> MissionOutput:
        err = self.targets - view.poses[:, :2]
        dist = np.linalg.norm(err, axis=1)
        v = self.gain * err
        cmds = track_velocity(view.poses, v, self.limits)
        cmds[dist < self.tolerance] = 0.0
        cmds[view.stale | ~view.present] = 0.0
        done = bool(np.all(dist < self.tolerance))
        return MissionOutput(commands=cmds, phase="goto" if not done else "done", done=done)


@dataclass
class HoldMission:
    """Keep every robot stopped (bring-up checks: poses flow, estop works); never ends."""

    n: int

    def step(self, view: FleetView) -> MissionOutput:
        return MissionOutput(commands=np.zeros((self.n, 3)), phase="hold")
