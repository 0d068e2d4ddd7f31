"""The transport's constants, derived from ``[transport]`` in one place, and those of its
stages (the grip, the route progress)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from controller.config import FleetConfig
from controller.mission.grip import GripSettings
from controller.mission.progress import ProgressSettings
from controller.mission.sequence import SequenceSettings

SEQUENCE = SequenceSettings(carry=True)  # the transport is the job carrying the object on


@dataclass(frozen=True)
class TransportSettings:
    """The transport mission's constants (SI). From ``[transport]``: ``tolerance`` (m) and
    ``heading_tolerance`` (rad) at the goal, ``stall_timeout`` (s). Internal: ``subgoal_tolerance``
    (m, rad: a subgoal counts as reached), ``corridor`` (m: farther from the route re-plans it),
    ``progress_step`` (m of progress that resets the stall clock), ``contact_tolerance`` (m: a
    robot this close to its contact point is in contact), ``back_off`` (m the robots withdraw
    from the delivered object), ``rearrange_timeout`` (s), ``waypoint_reached`` (m)."""

    tolerance: float = 0.2
    heading_tolerance: float = math.radians(10.0)
    stall_timeout: float = 10.0
    subgoal_tolerance: float = 0.1
    subgoal_heading: float = math.radians(8.0)
    corridor: float = 0.4
    progress_step: float = 0.02
    contact_tolerance: float = 0.15
    back_off: float = 0.25
    rearrange_timeout: float = 25.0  # s: then a new arrangement (and failed when futile)
    waypoint_reached: float = 0.08
    contact_gain: float = 1.5  # 1/s, pull back onto the contact point
    arrival_tolerance: float = 0.03  # m: a relocating robot this close to its contact arrived
    max_route_replans: int = 5
    progress_window: float = 0.6  # m of route ahead that the progress measure looks at
    settle_margin: float = 0.6  # the estimate must be this share of the tolerances from the goal
    accept_margin: float = 0.85  # ... or this share when the object stalls there
    stuck_plans: int = 3
    park_margin: float = 0.05  # m beyond the lane's band where idle robots wait
    turn_margin: float = 1.2  # a set chosen to turn the object produces this times the wrench
    max_rearrangements: int = 8  # re-arrangements in a row without progress, then stalled

    @classmethod
    def from_config(cls, cfg: FleetConfig) -> TransportSettings:
        t = cfg.transport
        return cls(
            tolerance=t.tolerance,
            heading_tolerance=math.radians(t.heading_tolerance_deg),
            stall_timeout=t.stall_timeout,
        )

    def grip(self) -> GripSettings:
        return GripSettings(
            self.contact_tolerance, self.arrival_tolerance, self.waypoint_reached, self.park_margin
        )

    def progress(self) -> ProgressSettings:
        return ProgressSettings(
            self.subgoal_tolerance,
            self.subgoal_heading,
            self.corridor,
            self.progress_step,
            self.stall_timeout,
            self.progress_window,
        )
