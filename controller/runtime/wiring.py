"""The composition root: the one place that wires controller/, drivers/ and sim_backend/.

``DryRun`` is ``fleet run``: a stand-in world behind sim drivers, one agent per robot on the
robot-side zenoh session, the controller node on its own session, the lockstep clock between
them, and the MCAP recorder on the controller's session. Everything crosses the bus.
"""

from __future__ import annotations

import logging

from controller.config import FleetConfig
from controller.estimation.fleet import FleetEstimator
from drivers.base import capabilities_of
from drivers.sim import SimDriver
from sim_backend.factory import make_world
from sim_backend.hub import SimHub
from sim_backend.sensors import make_sensors

log = logging.getLogger(__name__)


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
    from drivers.mavlink.driver import MavlinkDriver
    from drivers.mavlink.link import LinkPool
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
                    hub, r.id, capabilities_of(r), cfg.sim.pose_noise.xy, cfg.sim.pose_noise.theta
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
