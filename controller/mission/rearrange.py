"""The transport's re-arrangement stage (pure): when the contacts held cannot push the object
along its segment, a new set (Sharma's Eq. 5, ``controller.planning.arrangement``) is asked for
off the tick; when it comes, the transport has the grip move the robots nearest to its contacts
there (:meth:`Grip.regrip`) and this stage says who moves where. It changes nothing but its own
state: the grip only by the transport's hand."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.config import FleetConfig
from controller.events import RearrangeEvent
from controller.mission.grip import Grip
from controller.mission.planners import Planners, PlanSlot, spawn_rng
from controller.mission.types import Event, FleetView
from controller.planning.arrangement import Arrangement, plan_arrangement
from controller.planning.transport_model import ObjectModel


class Rearranger:
    """Asks for new contact sets and hands them to the grip. ``count``: re-arrangements so
    far; ``futile``: those since the object last made progress; ``since`` (s): when the last
    one was asked for, or its set came (its timeout counts from there)."""

    def __init__(
        self,
        cfg: FleetConfig,
        model: ObjectModel,
        speed: float,
        strategy: str,
        turn_margin: float,
        planners: Planners,
        rng: np.random.Generator,
    ) -> None:
        self.cfg, self.model, self.rng = cfg, model, rng
        self.speed, self.strategy, self.turn_margin = speed, strategy, turn_margin
        self._job = PlanSlot(planners, "rearrange")
        self.count = 0
        self.futile = 0
        self.since = 0.0

    def pause(self, dt: float) -> None:
        """An outage of ``dt`` s: the timeout does not run while it lasts."""
        self.since += dt

    def progressed(self) -> None:
        """The object made progress: the re-arrangements since are no longer futile."""
        self.futile = 0

    def doubted(self, new: Arrangement) -> bool:
        """A set short of the wrench its (turning) segment needs, taken on the benefit of the
        doubt, come again after a re-arrangement that brought no progress: the doubt is spent
        (the transport plans a push-limited route again from where the object lies)."""
        short = new.basis == "lp_capacity" and new.value * self.turn_margin < 1.0 - 1e-9
        return short and new.feasible and self.futile > 1

    @property
    def pending(self) -> bool:
        return self._job.pending

    def ask(self, t: float, direction: np.ndarray, active: list[int]) -> None:
        """Ask for new contacts for the unit twist ``direction`` (object frame) among the
        ``active`` robots; the robots hold until they come."""
        self.count += 1
        self.futile += 1
        self.since = t
        weakest = min(self.cfg.robots[i].max_force for i in active)
        self._job.request(
            t,
            plan_arrangement,
            self.cfg,
            self.model,
            direction,
            self.speed,
            weakest,
            len(active),
            self.turn_margin,
            spawn_rng(self.rng),
            self.strategy,
        )

    def take(self, t: float) -> Any:
        """The set asked for, once it has come (a ``PlanResult``), else None."""
        return self._job.take(t)

    def arranged(
        self,
        view: FleetView,
        new: Arrangement,
        direction: np.ndarray,
        grip: Grip,
        events: list[Event],
    ) -> None:
        """The new contacts have come and the grip has moved the nearest robots to them
        (:meth:`Grip.regrip`): the event says who moves where; the timeout counts from now."""
        self.since = view.t
        d = direction[:2]
        event = RearrangeEvent(
            t=view.t,
            direction=np.round(d if np.any(d) else np.array([1.0, 0.0]), 4).tolist(),
            pushers=new.pushers,
            basis=new.basis,
            eq5_value=float(new.value),
            moving=[view.ids[i] for i in grip.moves],
            contacts={view.ids[i]: np.round(c.point, 4).tolist() for i, c in grip.targets.items()},
        )
        events.append(event)
