"""The composition root: the one place that wires controller/, drivers/ and sim_backend/.

``DryRun`` is ``fleet run``: a stand-in world behind sim drivers, one agent per robot on the
robot-side zenoh session, the controller node on its own session, the lockstep clock between
them, and the MCAP recorder on the controller's session. Everything crosses the bus.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller import wire
from controller.bus import Bus
from controller.config import FleetConfig
from controller.estimation import FleetEstimator
from controller.node import ControllerNode, Mission
from controller.recorder import McapRecorder, config_metadata
from drivers.agent import Agent, AgentParams
from drivers.base import Capabilities
from drivers.lockstep import LockstepCoordinator
from drivers.sim import SimDriver
from sim_backend.factory import make_world
from sim_backend.hub import SimHub
from sim_backend.sensors import make_sensors

log = logging.getLogger(__name__)


def capabilities(robot) -> Capabilities:
    return Capabilities(
        kind=robot.kind,
        holonomic=robot.kind == "omni",
        max_speed=robot.max_speed,
        max_yaw_rate=robot.max_yaw_rate,
        radius=robot.radius,
    )


def make_hub(cfg: FleetConfig, gui: bool = False) -> SimHub:
    """The stand-in world named by ``sim.backend`` with its seeded sensors (sim-driven robots
    only: a MAVLink robot reports its own pose through its vehicle)."""
    world = make_world(cfg, gui=gui)
    sensors = make_sensors(cfg)
    sim_ids = {r.id for r in cfg.robots if r.driver == "sim"}
    robots = {rid: s for rid, s in sensors.robots.items() if rid in sim_ids}
    return SimHub(world, robots, sensors.object, cfg.sim.timestep)


def make_sim_drivers(cfg: FleetConfig, hub: SimHub, connect_timeout: float = 5.0):
    """One connected driver per robot of a dry run, and the MAVLink vehicle emulators.

    Sim robots get a SimDriver on the hub; MAVLink robots get the real MavlinkDriver talking
    over loopback UDP to an emulator that the hub pumps after every physics step, all on sim time.
    """
    from drivers.mavlink import LinkPool, MavlinkDriver
    from sim_backend.mavlink_vehicle import start_emulators

    def clock() -> float:
        return hub.t

    connected: list[MavlinkDriver] = []

    def idle(dt: float) -> None:
        # at least one physics step, or time would stand still; and keep the links of robots
        # already connected serviced (setpoint keepalive, heartbeats), as their agents would
        hub.advance_to(hub.t + max(dt, hub.dt))
        for d in connected:
            d.health()

    emulators = start_emulators(hub.world, cfg.robots, clock=clock)
    if emulators:
        hub.step_hooks.append(lambda t: [e.pump(t) for e in emulators])
    pool = LinkPool()
    drivers = []
    try:
        for r in cfg.robots:
            if r.driver == "mavlink":
                drv = MavlinkDriver(r, clock=clock, idle=idle, pool=pool)
            else:
                drv = SimDriver(
                    hub, r.id, capabilities(r), cfg.sim.pose_noise.xy, cfg.sim.pose_noise.theta
                )
            drv.connect(timeout=connect_timeout)
            drivers.append(drv)
            if isinstance(drv, MavlinkDriver):
                connected.append(drv)
    except BaseException:
        for d in drivers:
            d.close()
        for e in emulators:
            e.stop()
        raise
    return drivers, emulators


def make_estimator(cfg: FleetConfig) -> FleetEstimator:
    """Kalman filters for every robot and the object (``[estimation]``)."""
    return FleetEstimator(
        [(r.id, r.kind) for r in cfg.robots], cfg.estimation, cfg.fleet.stale_after
    )


@dataclass
class Verdict:
    """What the dry run measured against the hardware contract (Robotarium-style)."""

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


class ControllerLockstep:
    """The controller side of the lockstep: answers each SimTick with one node tick."""

    def __init__(self, node: ControllerNode, bus: Bus, wait_inputs: float) -> None:
        self.node = node
        self.ticks = bus.subscribe_topic("sim_clock")
        self.wait_inputs = wait_inputs
        self.stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="controller", daemon=True)
        self.lag_waits = 0
        self._deficit = 0  # measurements announced but never received (lost before matching)

    def _run(self) -> None:
        try:
            while not self.stop.is_set():
                item = self.ticks.get(timeout=0.1)
                if item is None:
                    continue
                tick: wire.SimTick = item.msg
                # handshake: every measurement published before the tick has been taken in
                deadline = time.monotonic() + self.wait_inputs
                while self.node.received + self._pending() + self._deficit < tick.seq:
                    if time.monotonic() > deadline:
                        self.lag_waits += 1
                        have = self.node.received + self._pending() + self._deficit
                        self._deficit += tick.seq - have
                        log.warning(
                            "tick %d: %d measurements never arrived", tick.step, tick.seq - have
                        )
                        break
                    time.sleep(0.0005)
                self.node.tick(tick.t, step=tick.step)
        except BaseException as exc:  # noqa: BLE001 - surfaced by the runner
            self.error = exc
            log.exception("controller loop failed")

    def _pending(self) -> int:
        return self.node.pending_measurements()


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
                    cfg, ctl_bus, self.mission, make_estimator(cfg), lossless_commands=True
                )
                drivers, emulators = make_sim_drivers(cfg, hub)
                agents = [
                    Agent(robot_bus, drv, AgentParams(r.id, cfg.fleet.name, cfg.fleet.cmd_ttl))
                    for r, drv in zip(cfg.robots, drivers, strict=True)
                ]
                coord = LockstepCoordinator(
                    robot_bus, hub, agents, control_dt, cfg.sim.tick_timeout
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
                summary = getattr(self.mission, "summary", dict)()
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


def _open_until(stop: threading.Event, cfg: FleetConfig, who: str) -> Bus | None:
    """A robot-side session to the daemon's endpoints, retried until it opens or ``stop``."""
    from controller.bus import BusError

    logged = False
    while not stop.is_set():
        try:
            return Bus(
                cfg.zenoh,
                cfg.fleet.name,
                listen=[],
                connect=list(cfg.zenoh.listen),
                lease_s=cfg.fleet.liveliness_lease,
            )
        except BusError as exc:
            if not logged:
                log.warning("%s: waiting for the bus: %s", who, exc)
                logged = True
            stop.wait(1.0)
    return None


def run_agent(
    cfg: FleetConfig,
    robot_id: str,
    stop: threading.Event,
    duration: float = 0.0,
    connect_timeout: float = 10.0,
) -> tuple[int, str]:
    """``fleet driver``: one robot's agent on the wall clock. Returns (exit status, message).

    A ``mavlink`` robot connects to its vehicle at its url; a ``sim`` robot runs alone in a
    real-time stand-in world of its own. Exit 1 when the robot does not answer or its link is
    lost (the robot is stopped first).
    """
    import dataclasses

    from controller.ratekeeper import Ratekeeper
    from drivers.base import DriverError
    from drivers.mavlink import MavlinkDriver

    robot = cfg.robot(robot_id)
    hub: SimHub | None = None
    # Stamps are wall-clock seconds (time.time): the daemon may run on another computer, and
    # NTP keeps lab machines within milliseconds; monotonic clocks are not comparable across them.
    wall0 = time.time()
    if robot.driver == "mavlink":
        driver = MavlinkDriver(robot, clock=time.time)
    else:
        solo = dataclasses.replace(cfg, robots=(robot,))
        hub = make_hub(solo)
        noise = cfg.sim.pose_noise
        driver = SimDriver(
            hub, robot.id, capabilities(robot), noise.xy, noise.theta, time_offset=wall0
        )
    try:
        driver.connect(timeout=connect_timeout)
    except DriverError as exc:
        return 1, str(exc)
    code, message = 0, ""
    try:
        bus = _open_until(stop, cfg, robot_id)
        if bus is None:
            return 0, ""
        with bus:
            agent = Agent(bus, driver, AgentParams(robot.id, cfg.fleet.name, cfg.fleet.cmd_ttl))
            rk = Ratekeeper(max(cfg.fleet.rate_hz, 20.0))
            log.info("robot %s: agent up (%s driver)", robot.id, robot.driver)
            while not stop.is_set():
                rk.keep_time()
                now = time.time()
                if hub is not None:
                    hub.advance_to(now - wall0)
                agent.step(now)
                if not agent.link_ok:
                    code, message = 1, "link lost: robot stopped"
                    break
                if duration and now - wall0 >= duration:
                    break
    finally:
        driver.close()
        if hub is not None:
            hub.world.close()
    return code, message
