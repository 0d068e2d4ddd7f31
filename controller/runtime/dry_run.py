"""``DryRun`` is ``fleet run``: a stand-in world behind sim drivers, one agent per robot on the
robot-side zenoh session, the controller node on its own session, the lockstep clock between
them, and the MCAP recorder on the controller's session. Everything crosses the bus.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller import wire
from controller.config import FleetConfig
from controller.io.bus import Bus
from controller.io.recorder import McapRecorder, config_metadata
from controller.mission.types import Mission
from controller.runtime.lockstep import ControllerLockstep, LockstepCoordinator
from controller.runtime.node import ControllerNode
from controller.runtime.wiring import make_estimator, make_hub, make_sim_drivers
from drivers.agent import Agent, AgentParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VerdictRules:
    """The hardware contract a run is judged by (Robotarium's "will / will NOT run on hardware"):
    the robot discs never overlap (gap ≥ ``min_robot_gap_m``), no robot enters the object deeper
    than ``max_object_penetration_m`` (contact is allowed, a contact patch of a centimetre is the
    solver's), no robot touches a static obstacle or a wall."""

    min_robot_gap_m: float = 0.0
    max_object_penetration_m: float = 0.01
    max_obstacle_contacts: int = 0


RULES = VerdictRules()


def judge(figures: Mapping[str, Any], rules: VerdictRules = RULES) -> list[dict[str, Any]]:
    """The one verdict: what in a run's figures breaks the contract (an empty list: clean).

    ``figures`` holds ``min_clearance_m`` (None: fewer than two robots or unknown),
    ``max_object_penetration_m`` (None: unknown) and ``obstacle_contacts`` (robot ids): the keys
    of ``fleet run --json`` and ``fleet replay --json``. Each failure is ``{reason, detail}``
    with reason ``collision``, ``penetration`` or ``obstacle_contact``.
    """
    out: list[dict[str, Any]] = []
    gap = figures.get("min_clearance_m")
    if gap is not None and gap < rules.min_robot_gap_m:
        out.append({"reason": "collision", "detail": f"robot-robot gap {gap:.4g} m"})
    depth = figures.get("max_object_penetration_m")
    if depth is not None and depth > rules.max_object_penetration_m:
        out.append({"reason": "penetration", "detail": f"a robot {depth:.4g} m inside the object"})
    contacts = list(figures.get("obstacle_contacts") or [])
    if len(contacts) > rules.max_obstacle_contacts:
        out.append({"reason": "obstacle_contact", "detail": f"robots {contacts} hit an obstacle"})
    return out


@dataclass
class Verdict:
    """What the dry run measured against the hardware contract, accumulated over the run."""

    min_clearance_m: float = math.inf
    max_object_penetration_m: float = 0.0
    obstacle_contacts: set[str] = field(default_factory=set)
    missed_ticks: int = 0
    watchdog_stops: int = 0
    clamped_commands: int = 0
    vy_dropped: int = 0

    def update(self, check) -> None:
        self.min_clearance_m = min(self.min_clearance_m, check.min_clearance)
        self.max_object_penetration_m = max(self.max_object_penetration_m, check.object_penetration)
        self.obstacle_contacts.update(check.obstacle_contacts)


def _add(a: dict[str, int], b: dict[str, int]) -> dict[str, int]:
    return {k: a.get(k, 0) + b.get(k, 0) for k in a.keys() | b.keys()}


class DryRun:
    """The pybullet (or ideal) dry run of a config, end to end over zenoh."""

    def __init__(
        self,
        cfg: FleetConfig,
        mission: Mission,
        out: Path,
        gui: bool = False,
        max_time: float | None = None,
    ) -> None:
        self.cfg = cfg
        self.mission = mission
        self.out = out
        self.gui = gui
        self.max_time = cfg.sim.max_time if max_time is None else max_time
        self.verdict = Verdict()

    def run(self) -> dict[str, Any]:
        cfg = self.cfg
        wall0 = time.monotonic()
        control_dt = 1.0 / cfg.fleet.rate_hz
        hub = make_hub(cfg, self.gui)
        world = hub.world
        recorder = McapRecorder(self.out, cfg.fleet.name, cfg.log.flush_interval)
        recorder.metadata("fleet.config", config_metadata(cfg, f"run/{cfg.sim.backend}"))
        arrested_at: list[float] = []
        result: dict[str, Any] = {}
        try:
            with (
                Bus(cfg.zenoh, cfg.fleet.name) as ctl_bus,
                Bus(
                    cfg.zenoh,
                    cfg.fleet.name,
                    listen=[],
                    connect=list(cfg.zenoh.listen),
                    lease_s=cfg.fleet.liveliness_lease,
                ) as robot_bus,
            ):
                ctl_bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample)
                node = ControllerNode(
                    cfg,
                    ctl_bus,
                    self.mission,
                    make_estimator(cfg),
                    lossless_commands=True,
                    extra_drops=recorder.drops,
                    clock=time.perf_counter,
                )
                drivers, emulators = make_sim_drivers(cfg, hub)
                commands_arrived = threading.Condition()
                agents = [
                    Agent(
                        robot_bus,
                        drv,
                        AgentParams(r.id, cfg.fleet.name, cfg.fleet.cmd_ttl),
                        commands_arrived,
                    )
                    for r, drv in zip(cfg.robots, drivers, strict=True)
                ]
                coord = LockstepCoordinator(
                    robot_bus, hub, agents, control_dt, cfg.sim.tick_timeout, commands_arrived
                )
                ctl = ControllerLockstep(node, ctl_bus, wait_inputs=cfg.sim.tick_timeout)

                def arrest() -> None:
                    if not world.arrested:
                        world.arrest()
                        arrested_at.append(world.t)

                coord.on_arrest = arrest
                self._handshake(node, agents, coord)
                ctl.thread.start()
                try:
                    while coord.t <= self.max_time:
                        coord.tick()
                        self.verdict.update(world.check())
                        if ctl.error is not None:
                            raise RuntimeError("controller loop failed") from ctl.error
                        out = node.last_output
                        if out is not None and (out.done or out.failed):
                            break
                        if cfg.sim.realtime:
                            lag = coord.t - (time.monotonic() - wall0)
                            if lag > 0:
                                time.sleep(lag)
                finally:
                    ctl.stop.set()
                    ctl.thread.join(timeout=10)
                for a in agents:
                    self.verdict.watchdog_stops += a.counters.watchdog_stops
                    self.verdict.clamped_commands += a.counters.clamped
                    self.verdict.vy_dropped += a.counters.vy_dropped
                    a.close()
                for e in emulators:
                    e.stop()
                self.verdict.missed_ticks = coord.counters.missed
                out = node.last_output
                summary = {**getattr(self.mission, "summary", dict)(), **node.timing_summary()}
                result = {
                    "phase": node.phase,
                    "done": bool(out.done) if out else False,
                    "failed": bool(out.failed) if out else False,
                    "arrested": world.arrested,
                    "arrest_time_s": arrested_at[0] if arrested_at else None,
                    "arrival_spread_s": summary.get("arrival_spread_s"),
                    "sim_time_s": round(coord.t, 4),
                    "ticks": coord.counters.ticks,
                    "node": dict(vars(node.counters)),
                    "bad_payloads": ctl_bus.stats.total + robot_bus.stats.total,
                    "drops": _add(node.drops(), robot_bus.drops()),
                    "final_object_pose": [float(v) for v in world.object_pose()],
                    "mission": summary,
                }
        finally:
            world.close()
            recorder.close()
        v = self.verdict
        result.update(
            {
                "min_clearance_m": None if math.isinf(v.min_clearance_m) else v.min_clearance_m,
                "max_object_penetration_m": v.max_object_penetration_m,
                "obstacle_contacts": sorted(v.obstacle_contacts),
                "missed_ticks": v.missed_ticks,
                "watchdog_stops": v.watchdog_stops,
                "clamped_commands": v.clamped_commands,
                "vy_dropped": v.vy_dropped,
                "wall_time_s": round(time.monotonic() - wall0, 3),
                "log": str(self.out),
                "messages_logged": recorder.written,
            }
        )
        result["verdict"] = judge(result)
        ok = result.get("done") and not result.get("failed") and not result["verdict"]
        result["status"] = "ok" if ok else "failed"
        return result

    def _handshake(self, node: ControllerNode, agents, coord, timeout: float = 20.0) -> None:
        """Wait until both sides see each other: the controller holds every robot's liveliness
        token, and every publisher on either side has a matching subscriber."""
        pubs = node.publishers_for_handshake() + coord.publishers_for_handshake()
        pubs += [a.pose_publisher for a in agents]
        deadline = time.monotonic() + timeout
        while True:
            up = int(np.count_nonzero(node.present))
            if up == len(agents) and all(p.matching() for p in pubs):
                return
            if time.monotonic() > deadline:
                unmatched = [p.key for p in pubs if not p.matching()]
                raise RuntimeError(
                    f"{up} of {len(agents)} robots came up; unmatched keys: {unmatched}"
                )
            time.sleep(0.01)
