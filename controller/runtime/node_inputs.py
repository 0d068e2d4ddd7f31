"""The controller node's inputs: the robots' and the object's poses into the filters (a stamp
off the tick's clock dropped or taken at the tick), the robots' presence (liveliness tokens)
and their link events, believed only when the token agrees.

Part of ``ControllerNode`` (``controller/runtime/node.py``): its sample stage calls ``sample``.
The counters and the estimator's protocol live here, shared by the node's parts.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from controller import wire
from controller.config import FleetConfig
from controller.events import LinkLostEvent, LinkRestoredEvent, link_event

log = logging.getLogger("controller.runtime.node")  # the node's own log, whichever part

# s: a pose stamped at most this after the tick is taken as stamped (float rounding of sim time,
# sub-tick sensor timing); later stamps are taken at the tick
AHEAD_TOLERANCE = 1e-3
# s (in ticks): how long a robot's link event may wait for its liveliness token to agree
EVENT_GRACE = 1.0


class Estimator(Protocol):
    def command(self, robot_id: str, t: float, vx: float, vy: float, wz: float) -> None: ...
    def measure_robot(self, robot_id: str, t: float, x: float, y: float, theta: float) -> str: ...
    def measure_robots(self, items: list[tuple[str, float, float, float, float]]) -> list[str]: ...
    def measure_object(self, t: float, x: float, y: float, theta: float) -> str: ...
    def robot_arrays(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    def robot_estimate(self, robot_id: str, now: float) -> Any: ...
    def object_estimate(self, now: float) -> Any: ...
    def predict_object(self, now: float, horizon: float) -> Any: ...
    def set_object_arrested(self, arrested: bool) -> None: ...
    def push_object(self, t: float, vx: float, vy: float, wz: float) -> None: ...


@dataclass
class NodeCounters:
    ticks: int = 0
    poses: int = 0
    object_poses: int = 0
    rejected: int = 0
    out_of_order: int = 0
    commands: int = 0
    link_events: int = 0
    link_restored: int = 0
    skewed: int = 0  # poses stamped further than fleet.max_clock_skew from the tick time
    over_budget: int = 0  # lab ticks that took longer than fleet.tick_budget
    ahead: int = 0  # poses stamped > 1 ms after the tick time (within the skew): taken at the tick
    spoofed_events: int = 0  # link events the robot's liveliness token did not bear out


def known(estimate: Any) -> Any:
    """The estimate, or None before its first measurement."""
    if estimate is None or not getattr(estimate, "initialized", True):
        return None
    return estimate


class NodeInputs:
    """What the controller hears of the robots and the object, in per-robot arrays in the
    config's robot order (``present``, ``link_lost``, ``skewed``)."""

    def __init__(
        self,
        cfg: FleetConfig,
        bus,
        counters: NodeCounters,
        lossless: bool,
        news_over: Callable[[], bool],
        rings: bool = False,
        pose_tap: Callable[[str, bytes, float], None] | None = None,
    ) -> None:
        """``lossless``: the lockstep dry run's inboxes (nothing dropped); ``news_over``: whether
        a robot leaving is the expected end (the job over, the process stopping). ``rings``
        (the lab daemon): the robots' and the object's poses are read from one zenoh ring per
        key at each tick (``Bus.subscribe_rings``), so a robot flooding its pose key costs the
        loop nothing; ``pose_tap`` gets every pose read (the recorder)."""
        self.cfg = cfg
        self.ids = cfg.robot_ids
        self.index = {rid: i for i, rid in enumerate(self.ids)}
        self.counters = counters
        self._news_over = news_over
        self.present = np.zeros(len(self.ids), dtype=bool)
        # the robot's last pose was dropped for its stamp (its clock is off): ``fleet status``
        # says ``skewed``; the first such drop of a robot (and the next after a good pose) logged
        self.skewed = np.zeros(len(self.ids), dtype=bool)
        self.link_lost = np.zeros(len(self.ids), dtype=bool)
        self._events_pending: dict[str, tuple[LinkLostEvent | LinkRestoredEvent, int]] = {}
        self.arrived = threading.Condition()  # notified on every pose (lockstep waits)
        # bounded per robot (a flood drops the oldest), lossless in the lockstep dry run
        if rings:
            self._poses = bus.subscribe_rings("robot_pose", self.ids, pose_tap)
            self._object = bus.subscribe_rings("object_pose", (), pose_tap)
        else:
            self._poses = bus.subscribe_topic("robot_pose", waker=self.arrived, lossless=lossless)
            self._object = bus.subscribe_topic("object_pose", waker=self.arrived, lossless=lossless)
        self._robot_events = bus.subscribe_topic("robot_event")
        bus.watch_alive("robot", self._on_alive)

    def _on_alive(self, rid: str, alive: bool) -> None:
        i = self.index.get(rid)
        if i is None:
            return
        if self.present[i] != alive:
            # a robot leaving during the job is news (WARNING); after it, or while the process
            # stops (its agents close), it is the expected end (INFO)
            quiet = alive or self._news_over()
            log.log(logging.INFO if quiet else logging.WARNING, "robot %s %s", rid,
                    "present" if alive else "gone")  # fmt: skip
        self.present[i] = alive

    def sample(self, est: Estimator, now: float | None) -> None:
        """Link events, then every pose received into ``est``. With ``now`` (the tick time: the
        same clock domain as the stamps) a pose stamped further than ``fleet.max_clock_skew``
        from it is dropped and counted (``skewed``), and one after it is taken at ``now``."""
        self._sample_events()
        items = []
        for item in self._poses.drain():
            rid = self._robot_id(item.key)
            if rid not in self.index:
                continue
            m = item.msg
            if self._skewed(m.t, now, self.index[rid]):
                continue
            items.append((rid, self._stamp(m.t, now), m.x, m.y, m.theta))
        if items:  # the tick's poses through the filters at once (stacked per model)
            res = est.measure_robots(items)
            self.counters.poses += len(res)
            self.counters.rejected += res.count("rejected")
            self.counters.out_of_order += res.count("out_of_order")
        for item in self._object.drain():
            m = item.msg
            if self._skewed(m.t, now):
                continue
            est.measure_object(self._stamp(m.t, now), m.x, m.y, m.theta)
            self.counters.object_poses += 1

    def _sample_events(self) -> None:
        """Robot events, believed only when the robot's liveliness token agrees: its agent
        withdraws the token before it reports ``link_lost`` and declares it before
        ``link_restored``. An event the token does not bear out within ``EVENT_GRACE`` s of
        ticks is ignored and counted (``spoofed_events``): on the open default anyone may put
        on a robot's event key (under the lab ACL only that robot's agent may)."""
        for item in self._robot_events.drain():
            rid = self._robot_id(item.key)
            ev = link_event(item.msg.kind, item.msg.data)
            if rid in self.index and ev is not None:
                until = self.counters.ticks + max(1, round(EVENT_GRACE * self.cfg.fleet.rate_hz))
                self._events_pending[rid] = (ev, until)
        for rid, (ev, until) in list(self._events_pending.items()):
            i = self.index[rid]
            if bool(self.present[i]) == isinstance(ev, LinkRestoredEvent):
                del self._events_pending[rid]
                self._apply_event(rid, ev)
            elif self.counters.ticks >= until:
                del self._events_pending[rid]
                self.counters.spoofed_events += 1
                log.warning(
                    "robot %s: %s ignored: its liveliness token says otherwise (not its agent)",
                    rid,
                    ev.kind,
                )

    def _apply_event(self, rid: str, ev: LinkLostEvent | LinkRestoredEvent) -> None:
        i = self.index[rid]
        if isinstance(ev, LinkLostEvent):
            self.link_lost[i] = True
            self.counters.link_events += 1
            log.error("robot %s reports a lost link: %s", rid, ev.detail)
        else:
            if self.link_lost[i]:
                log.warning("robot %s: link restored (%s)", rid, ev.detail)
            self.link_lost[i] = False
            self.counters.link_restored += 1

    def _skewed(self, t: float, now: float | None, robot: int | None = None) -> bool:
        """Whether a pose stamped ``t`` is too far from the tick ``now`` (dropped, counted; a
        robot's first in a row logged with the offset, so a robot whose clock is off is named)."""
        if now is None or abs(t - now) <= self.cfg.fleet.max_clock_skew:
            if robot is not None:
                self.skewed[robot] = False
            return False
        self.counters.skewed += 1
        if robot is not None and not self.skewed[robot]:
            self.skewed[robot] = True
            log.warning(
                "robot %s: its poses are stamped %+.3f s from the controller's clock, beyond "
                "fleet.max_clock_skew (%.3f s): dropped until its clock agrees (NTP or chrony "
                "on the robot's computer)",
                self.ids[robot],
                t - now,
                self.cfg.fleet.max_clock_skew,
            )
        elif self.counters.skewed == 1 or self.counters.skewed % 100 == 0:
            log.warning(
                "dropped a pose stamped %.3f s at tick %.3f s (%d so far)",
                t,
                now,
                self.counters.skewed,
            )
        return True

    def _stamp(self, t: float, now: float | None) -> float:
        """A pose's stamp, but never after the tick: a measurement from the future (a fast
        clock, or a spoofer inside the skew) is taken as made at the tick, so it cannot
        extrapolate a filter past the tick nor push its timeline ahead (counted: ``ahead``).
        Up to ``AHEAD_TOLERANCE`` after the tick a stamp is kept (rounding, not a clock)."""
        if now is None or t <= now + AHEAD_TOLERANCE:
            return t
        self.counters.ahead += 1
        return now

    def _robot_id(self, key: str) -> str:
        parsed = wire.parse_key(key, self.cfg.fleet.name)
        return "" if parsed is None else parsed.id

    def pending(self) -> int:
        """Pose measurements received but not yet taken in."""
        return self._poses.qsize() + self._object.qsize()
