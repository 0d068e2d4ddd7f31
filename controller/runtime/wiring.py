"""The composition root: the one place that wires controller/, drivers/ and sim_backend/.

The driver registry: :data:`DRIVER_CLASSES` maps each ``robots[].driver`` name (its config
entry is ``controller.config.DRIVER_SPECS``) to how its class is built, in a dry run and for
``fleet driver``. A new driver registers here and in the config, plus its own module.

``DryRun`` is ``fleet run``: a stand-in world behind sim drivers, one agent per robot on the
robot-side zenoh session, the controller node on its own session, the lockstep clock between
them, and the MCAP recorder on the controller's session. Everything crosses the bus.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from controller.config import DRIVER_SPECS, FleetConfig, RobotConfig
from controller.estimation.fleet import FleetEstimator
from drivers.base import capabilities_of
from drivers.sim import SimDriver
from sim_backend.factory import make_world
from sim_backend.hub import SimHub
from sim_backend.sensors import make_sensors

log = logging.getLogger(__name__)


def make_hub(cfg: FleetConfig, gui: bool = False) -> SimHub:
    """The stand-in world named by ``sim.backend`` with its seeded sensors (robots that are
    bodies of the world only: a MAVLink robot reports its own pose through its vehicle)."""
    world = make_world(cfg, gui=gui)
    sensors = make_sensors(cfg)
    sim_ids = {r.id for r in cfg.robots if r.spec.world_body}
    robots = {rid: s for rid, s in sensors.robots.items() if rid in sim_ids}
    return SimHub(world, robots, sensors.object, cfg.sim.timestep)


# --------------------------------------------------------------------------- driver classes


@dataclass
class DryRunLinks:
    """What the drivers of one dry run share: the hub, its sim clock, the MAVLink link pool,
    and ``idle(dt)`` that advances the sim while a driver waits (servicing the ``serviced``
    drivers already connected: setpoint keepalive and heartbeats, as their agents would)."""

    hub: SimHub
    pool: Any = None
    serviced: list[Any] = field(default_factory=list)

    def clock(self) -> float:
        return self.hub.t

    def idle(self, dt: float) -> None:
        # at least one physics step, or time would stand still
        self.hub.advance_to(self.hub.t + max(dt, self.hub.dt))
        for d in self.serviced:
            d.health()


@dataclass(frozen=True)
class DriverClass:
    """How the runtime builds one driver (``robots[].driver``; its config entry, sub-table and
    ACL needs are ``controller.config.DRIVER_SPECS[name]``).

    ``dry_run(links, cfg, robot)``: the driver in the lockstep dry run (``fleet run``);
    ``keepalive``: a dry run services it while others connect. ``local(cfg, robot, wall0,
    strict)``: ``fleet driver``'s driver when it needs no bus to connect, and the real-time
    world of its own or None; ``over_bus(cfg)``: whether ``fleet driver`` builds it on the bus
    instead, with ``remote(bus, cfg, robot)`` (e.g. a sim robot of the ``fleet world`` process).
    ``holds_on_loss``: a lost link does not end ``fleet driver``: its agent holds the robot
    stopped, keeps its driver (and the link's session) and reports ``link_restored`` when the
    robot answers again (a robot of the world process always does, over the bus)."""

    name: str
    dry_run: Callable[[DryRunLinks, FleetConfig, RobotConfig], Any]
    local: Callable[[FleetConfig, RobotConfig, float, bool], tuple[Any, SimHub | None]]
    keepalive: bool = False
    over_bus: Callable[[FleetConfig], bool] = lambda cfg: False
    remote: Callable[[Any, FleetConfig, RobotConfig], Any] | None = None
    holds_on_loss: bool = False


DRIVER_CLASSES: dict[str, DriverClass] = {}


def register_driver_class(entry: DriverClass) -> DriverClass:
    """Add a driver class under a name of ``controller.config.DRIVER_SPECS``."""
    if entry.name not in DRIVER_SPECS:
        raise ValueError(
            f"driver {entry.name!r} has no config entry; register_driver() it in "
            f"controller.config first (known: {tuple(DRIVER_SPECS)})"
        )
    DRIVER_CLASSES[entry.name] = entry
    return entry


def driver_class(robot: RobotConfig) -> DriverClass:
    """The registered class entry of the robot's driver."""
    return DRIVER_CLASSES[robot.driver]


def _sim_dry_run(links: DryRunLinks, cfg: FleetConfig, r: RobotConfig) -> Any:
    noise = cfg.sim.pose_noise
    return SimDriver(links.hub, r.id, capabilities_of(r), noise.xy, noise.theta)


def _sim_local(cfg: FleetConfig, r: RobotConfig, wall0: float, strict: bool) -> tuple[Any, Any]:
    """A sim robot alone in a real-time world of its own (``sim.world = "solo"``)."""
    hub = make_hub(dataclasses.replace(cfg, robots=(r,)))
    noise = cfg.sim.pose_noise
    driver = SimDriver(hub, r.id, capabilities_of(r), noise.xy, noise.theta, time_offset=wall0)
    return driver, hub


def _remote_sim(bus: Any, cfg: FleetConfig, r: RobotConfig) -> Any:
    """A sim robot of the shared ``fleet world`` process, over the bus (``sim.world =
    "process"``)."""
    from drivers.remote_sim import RemoteSimDriver

    return RemoteSimDriver(bus, r.id, capabilities_of(r), clock=time.time)


def _mavlink_dry_run(links: DryRunLinks, cfg: FleetConfig, r: RobotConfig) -> Any:
    from drivers.mavlink.driver import MavlinkDriver
    from drivers.mavlink.link import LinkPool

    if links.pool is None:
        links.pool = LinkPool()
    return MavlinkDriver(r, clock=links.clock, idle=links.idle, pool=links.pool)


def _mavlink_local(cfg: FleetConfig, r: RobotConfig, wall0: float, strict: bool):
    from drivers.mavlink.driver import MavlinkDriver

    return MavlinkDriver(r, clock=time.time, strict=strict, keepalive_thread=True), None


register_driver_class(
    DriverClass(
        "sim",
        _sim_dry_run,
        _sim_local,
        over_bus=lambda cfg: cfg.sim.world == "process",
        remote=_remote_sim,
    )
)
register_driver_class(DriverClass("mavlink", _mavlink_dry_run, _mavlink_local, keepalive=True))


def ros2_settings(r: RobotConfig) -> Any:
    """A ROS 2 robot's ``[robots.ros2]`` table as the driver's settings."""
    from drivers.ros2.driver import Ros2Settings

    s = r.ros2
    return Ros2Settings(**{f.name: getattr(s, f.name) for f in dataclasses.fields(s)})


def _ros2_dry_run(links: DryRunLinks, cfg: FleetConfig, r: RobotConfig) -> Any:
    """Refused (bad input, exit 2): a ROS 2 robot is a vehicle of its own."""
    from controller.config import InputError

    raise InputError(
        f"robot {r.id!r}: a ros2 robot is a vehicle of its own, not a body of the dry run's "
        "world; run it with `fleet driver` against the robot (or the stand-in, "
        "tests/support/ros2_robot.py)"
    )


def _ros2_local(cfg: FleetConfig, r: RobotConfig, wall0: float, strict: bool):
    from drivers.ros2.driver import Ros2Driver

    driver = Ros2Driver(
        r.id, capabilities_of(r), ros2_settings(r), stale_after=cfg.fleet.stale_after
    )
    return driver, None


# a ROS 2 robot's odometry falling silent (Wi-Fi, its router restarted) is not the end of its
# agent: it holds the robot stopped and rejoins when the odometry returns
register_driver_class(DriverClass("ros2", _ros2_dry_run, _ros2_local, holds_on_loss=True))


def make_sim_drivers(cfg: FleetConfig, hub: SimHub, connect_timeout: float = 5.0):
    """One connected driver per robot of a dry run, and the MAVLink vehicle emulators.

    Each robot's driver comes from :data:`DRIVER_CLASSES`: sim robots get a SimDriver on the
    hub; MAVLink robots get the real MavlinkDriver talking over loopback UDP to an emulator
    that the hub pumps after every physics step, all on sim time.
    """
    from sim_backend.mavlink_vehicle import start_emulators

    links = DryRunLinks(hub)
    emulators = start_emulators(hub.world, cfg.robots, clock=links.clock)
    if emulators:
        hub.step_hooks.append(lambda t: [e.pump(t) for e in emulators])
    drivers = []
    try:
        for r in cfg.robots:
            entry = driver_class(r)
            drv = entry.dry_run(links, cfg, r)
            drv.connect(timeout=connect_timeout)
            drivers.append(drv)
            if entry.keepalive:
                links.serviced.append(drv)
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
