"""The transport's constants, derived from ``[transport]`` in one place, and those of its
stages (the grip, the route progress), which it holds.

A default that a config key sets is written once, in ``controller/config`` (``configured``):
``TransportSettings.from_config`` takes those keys of ``[transport]`` for itself and for the
stages' settings it holds; every other field is an internal constant."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from controller.config import FleetConfig, TransportSection, configured, from_section
from controller.mission.grip import GripSettings
from controller.mission.progress import ProgressSettings
from controller.mission.sequence import SequenceSettings
from controller.planning.arrangement import TURN_MARGIN

SEQUENCE = SequenceSettings(carry=True)  # the transport is the job carrying the object on
_TRANSPORT = TransportSection()  # the config's defaults: the settings' defaults of its keys


@dataclass(frozen=True)
class TransportSettings:
    """The transport mission's constants (SI). From ``[transport]``: ``tolerance`` (m) and
    ``heading_tolerance`` (rad) at the goal, and ``progress.stall_timeout`` (s). The stages'
    settings: ``grip`` (contacts, arrivals, parking) and ``progress`` (subgoals, corridor,
    stalls). Internal: ``back_off`` (m the robots withdraw from the delivered object),
    ``rearrange_timeout`` (s), ``contact_gain`` (1/s) and the margins and counts below."""

    tolerance: float = configured(_TRANSPORT, "tolerance")
    heading_tolerance: float = configured(_TRANSPORT, "heading_tolerance_deg", math.radians)
    grip: GripSettings = field(default_factory=GripSettings)
    progress: ProgressSettings = field(default_factory=ProgressSettings)
    back_off: float = 0.25
    rearrange_timeout: float = 25.0  # s: then a new arrangement (and failed when futile)
    contact_gain: float = 1.5  # 1/s, pull back onto the contact point
    max_route_replans: int = 5
    settle_margin: float = 0.6  # the estimate must be this share of the tolerances from the goal
    accept_margin: float = 0.85  # ... or this share when the object stalls there
    stuck_plans: int = 3
    turn_margin: float = TURN_MARGIN  # a set chosen by the LP produces this times the wrench
    max_rearrangements: int = 8  # re-arrangements in a row without progress, then stalled

    @property
    def stall_timeout(self) -> float:
        """s without progress before the transport is stalled (``transport.stall_timeout``)."""
        return self.progress.stall_timeout

    @classmethod
    def from_config(cls, cfg: FleetConfig) -> TransportSettings:
        t = cfg.transport
        return from_section(cls, t, progress=from_section(ProgressSettings, t))
