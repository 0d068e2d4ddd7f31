"""Who takes part in the job (pure): the one wait for the first estimates, robots gone
(liveliness or link lost, or stale too long while capturing), lost and joining again (during
the capture), and robots never seen parked out of the way in the views the planners read. The
job holds one roster for every phase."""

from __future__ import annotations

import dataclasses

import numpy as np

from controller.events import RobotJoinedEvent, RobotLostEvent
from controller.mission.types import Event, FleetView

# s a robot's estimate may stay stale (no pose for fleet.stale_after) before the capture takes
# the robot for lost (a robot whose liveliness token or link is gone is lost at once)
LOST_STALE_S = 0.5
PARK = 1.0e3  # m: a robot never seen is parked this far away in the views the capture reads


class Roster:
    """``available`` (N,): robots an assignment may use; ``lost``: robots lost during the
    job, in order; ``first_t`` (s): the first estimates (a robot's or the object's)."""

    def __init__(self, n: int) -> None:
        self.available = np.ones(n, bool)
        self.lost: list[int] = []
        self.stale_since = np.full(n, np.nan)  # s: when each estimate turned stale
        self.silent = np.zeros(n, bool)  # gone by a stale estimate alone (liveliness still up)
        self.first_t: float | None = None

    def start_with(self, ready: np.ndarray) -> None:
        """The capture starts with the robots ``ready`` (N,): the ones an assignment may use."""
        self.available = np.asarray(ready, bool).copy()

    def seen(self, view: FleetView) -> np.ndarray:
        """(N,) robots present with a fresh estimate (and the first estimates' time noted)."""
        ready = np.asarray(view.present & ~view.stale, bool)
        if self.first_t is None and (view.object_pose is not None or ready.any()):
            self.first_t = view.t
        return ready

    def gone(self, view: FleetView, carrying: bool = False) -> np.ndarray:
        """(N,) robots gone this tick: liveliness or link lost, or (capturing) stale for
        ``LOST_STALE_S``. While the object is carried only the liveliness and the link count:
        a robot pushing it whose poses pause keeps its contact (the gate and the estimator
        cover a pause; its agent's watchdog stops it when the commands stop)."""
        stale = np.asarray(view.stale, bool)
        self.stale_since[~stale] = np.nan
        self.stale_since[stale & np.isnan(self.stale_since)] = view.t
        held = stale & (view.t - np.nan_to_num(self.stale_since, nan=view.t) >= LOST_STALE_S)
        if carrying:
            held = np.zeros_like(held)
        present = np.asarray(view.present, bool)
        self.silent = held & present
        return ~present | held

    def joins(self, view: FleetView, gone: np.ndarray) -> list[Event]:
        """Robots present with a fresh estimate again (or seen at last) are available again."""
        back = ~self.available & ~gone & view.present & ~view.stale
        self.available |= back
        return [RobotJoinedEvent(t=view.t, robot=view.ids[i]) for i in np.flatnonzero(back)]

    def losses(
        self, view: FleetView, gone: np.ndarray, assignment: np.ndarray | None, phase: str
    ) -> tuple[list[int], list[Event], bool]:
        """Robots lost this tick (indices, events), and whether one of them held a capture
        point of ``assignment`` (None: the carry, where the event does not say)."""
        new = [int(i) for i in np.flatnonzero(gone & self.available)]
        self.available[new] = False
        self.lost += new
        assigned = set() if assignment is None else {int(i) for i in assignment}
        events: list[Event] = [
            RobotLostEvent(
                t=view.t,
                robot=view.ids[i],
                phase=phase,
                assigned=None if assignment is None else i in assigned,
            )
            for i in new
        ]
        return new, events, any(i in assigned for i in new)


def parked(view: FleetView) -> FleetView:
    """The view with robots never seen (no estimate: NaN) parked far away, standing still: the
    planners and the safety filter read every robot's pose."""
    unknown = ~np.all(np.isfinite(view.poses), axis=1)
    if not unknown.any():
        return view
    poses, vels = view.poses.copy(), view.velocities.copy()
    k = np.flatnonzero(unknown)
    poses[k] = np.stack([PARK + 10.0 * k, np.full(len(k), PARK), np.zeros(len(k))], 1)
    vels[k] = 0.0
    return dataclasses.replace(view, poses=poses, velocities=vels)
