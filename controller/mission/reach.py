"""Whether the capture points stay within the robots' reach (pure): a point a wall or an
obstacle takes (a robot's disc cannot stand at its station) for ``PIN_TICKS`` ticks, or a robot
that comes no closer to its station while the object is at rest (a notch a wall closes, a gap
too narrow to pass: its point and the nodes around it are excluded). Either asks the job for a
capture re-plan there (the wall a fixed contact)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView, Phase
from controller.planning.capture_set import CaptureSet

PIN_TICKS = 10  # ticks a capture point must stay blocked by a wall before the capture re-plans
MAX_REPLANS = 8  # capture re-plans at walls before the set stands as it is
STUCK_S = 8.0  # s a robot may come no closer to its station (object at rest) before its point
STUCK_PROGRESS = 0.05  # m  ... is taken for out of reach and the capture re-planned without it
STUCK_POCKET = 0.3  # m around a stuck point whose nodes are excluded with it
STUCK_OBJECT_MOVE = 0.1  # m the object may move (estimate) and still count as at rest


class Reach:
    """``unreachable``: candidate nodes robots could not get to; ``replans``: re-plans at walls
    so far (the job counts them as they come)."""

    def __init__(self, cfg: FleetConfig) -> None:
        self.cfg = cfg
        self.blocked_ticks = 0
        self.replans = 0
        self.unreachable: set[int] = set()
        self.progress: tuple[np.ndarray, np.ndarray, np.ndarray, Any] | None = None

    def restart(self) -> None:
        """A new approach (a re-plan asked or done): the blocked count starts again."""
        self.blocked_ticks = 0

    def wait(self, dt: float) -> None:
        """``dt`` s the job was held (an e-stop): a robot held still is not stuck."""
        if self.progress is not None:
            self.progress[1][:] += dt

    def replanned(self) -> None:
        """A capture re-planned against the wall (counted: at most MAX_REPLANS)."""
        self.replans += 1

    def blocked(
        self, view: FleetView, phase: str, capture: CaptureSet, dist: Any, approach: Any
    ) -> bool:
        """Whether some capture point has been out of a robot's reach (a wall or an obstacle
        where its disc must go) for ``PIN_TICKS`` ticks, before the fleet closes in, or a robot
        is stuck on the way to it. ``dist`` (M,): each robot to its station (None: unknown);
        ``approach``: the approach under way (a new one starts the stuck clocks again)."""
        if phase not in (Phase.APPROACH, Phase.CLOSE_IN) or self.replans >= MAX_REPLANS:
            return False
        if phase == Phase.APPROACH and dist is not None:
            if self._stuck(view, capture, dist, approach):
                return True
        cfg = self.cfg
        r = cfg.max_robot_radius
        centres = geometry.transform(
            capture.points + (r + cfg.capture.clearance) * capture.normals, view.object_pose
        )
        bounds = cfg.bounds_array() if cfg.world.walls else None
        hit = geometry.discs_touch_static(
            centres, r + cfg.approach.safety_margin, cfg.obstacle_polygons(), bounds, slack=0.0
        )
        self.blocked_ticks = self.blocked_ticks + 1 if hit.any() else 0
        return self.blocked_ticks >= PIN_TICKS

    def _stuck(self, view: FleetView, capture: CaptureSet, dist: np.ndarray, approach) -> bool:
        """With the object at rest, some robot has come no closer to its station by
        ``STUCK_PROGRESS`` m for ``STUCK_S`` s: its point (and the nodes around it) excluded."""
        xy = np.asarray(view.object_pose[:2], float)
        fresh = self.progress is None or self.progress[3] is not approach
        if fresh or np.linalg.norm(xy - self.progress[2]) > STUCK_OBJECT_MOVE:
            # (re)start: a moving object is chased, not stuck on (its pose, not its noisy speed)
            self.progress = (dist.copy(), np.full(len(dist), view.t), xy, approach)
        best, since, _, _ = self.progress
        better = dist < best - STUCK_PROGRESS
        best[better], since[better] = dist[better], view.t
        stuck = (view.t - since > STUCK_S) & (dist > self.cfg.approach.envelope_tolerance)
        if not stuck.any():
            return False
        # the nodes around a stuck point are in the same pocket: exclude them together
        cand = capture.candidates
        for m in np.flatnonzero(stuck):
            near = np.linalg.norm(cand - capture.points[m], axis=1) < STUCK_POCKET
            self.unreachable |= {int(i) for i in np.flatnonzero(near)}
        return True
