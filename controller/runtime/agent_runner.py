"""``fleet driver``: one robot's agent on the wall clock (the robot side of the lab)."""

from __future__ import annotations

import logging
import math
import threading
import time
from contextlib import AbstractContextManager, nullcontext

from controller.config import FleetConfig
from controller.io.bus import Bus
from controller.runtime.sole import already_served
from controller.runtime.wiring import driver_class
from drivers.agent import Agent, AgentParams
from sim_backend.hub import SimHub

log = logging.getLogger(__name__)

LATCH_WAIT = 2.0  # s an agent waits at start for a holder of the latched e-stop to answer
LATCH_EVERY = 2.0  # s between the agent's later latch queries
BEHIND_S = 1.0  # s: an agent's own world this far behind the clock is said to be (once)


def robot_bus(cfg: FleetConfig, who: str) -> Bus:
    """Robot ``who``'s session: a client of the daemon's (or hub's) endpoints, with the short
    liveliness lease and the robot's own zenoh identity. Raises BusError if it cannot open."""
    return Bus(
        cfg.zenoh,
        cfg.fleet.name,
        mode="client",  # through the hub only: no peer links around its ACL
        listen=[],
        connect=list(cfg.zenoh.listen),
        lease_s=cfg.fleet.liveliness_lease,
        identity=cfg.zenoh_identity(who),
    )


def robot_estop_path(cfg: FleetConfig, who: str) -> AbstractContextManager[Bus | None]:
    """Robot ``who``'s session on the e-stop's second path (``zenoh.estop_listen``, the
    daemon's own listener), or None (as a context) when there is none. A peer that listens
    nowhere and gossips with nobody: it opens while the daemon is down and reaches it when it
    comes (no link around the hub's ACL: only to the daemon's router, under the same rules)."""
    from controller.io.bus import BusError

    if not cfg.zenoh.estop_listen:
        return nullcontext(None)
    try:
        return Bus(
            cfg.zenoh,
            cfg.fleet.name,
            mode="peer",
            listen=[],
            connect=list(cfg.zenoh.estop_listen),
            lease_s=cfg.fleet.liveliness_lease,
            identity=cfg.zenoh_identity(who),
        )
    except BusError as exc:
        log.error("%s: the e-stop's second path cannot open (%s): the hub's only", who, exc)
        return nullcontext(None)


def _open_until(stop: threading.Event, cfg: FleetConfig, who: str) -> Bus | None:
    """A robot-side session to the daemon's endpoints as robot ``who``'s own zenoh identity,
    retried until it opens or ``stop`` (a wrong password is refused like an absent hub)."""
    from controller.io.bus import BusError

    logged = False
    while not stop.is_set():
        try:
            return robot_bus(cfg, who)
        except BusError as exc:
            if not logged:
                log.warning("%s: waiting for the bus: %s", who, exc)
                logged = True
            stop.wait(1.0)
    return None


def uses_world_process(cfg: FleetConfig, robot) -> bool:
    """Whether ``fleet driver`` builds this robot's driver over the bus (a sim robot of the
    shared ``fleet world`` process: ``sim.world = "process"``)."""
    return driver_class(robot).over_bus(cfg)


def run_agent(
    cfg: FleetConfig,
    robot_id: str,
    stop: threading.Event,
    duration: float = 0.0,
    connect_timeout: float = 60.0,
    *,
    strict: bool = False,
) -> tuple[int, str]:
    """``fleet driver``: one robot's agent on the wall clock. Returns (exit status, message).

    A ``mavlink`` robot connects to its vehicle at its url; a ``sim`` robot runs alone in a
    real-time stand-in world of its own, or, with ``sim.world = "process"``, is the robot of
    that id in the shared ``fleet world`` process (reached over the bus). Exit 1 when the robot
    does not answer at start or (a MAVLink robot) its link is lost (the robot is stopped first);
    a robot of the world process or a ROS 2 robot (``DriverClass.holds_on_loss``) instead
    waits, stopped, for its link to come back (``link_lost``, then ``link_restored``).
    ``strict``: a MAVLink vehicle whose own setpoint timeout is longer than
    ``max_vehicle_timeout`` (or unreadable) is refused (exit 1).
    """
    from drivers.base import DriverError

    robot = cfg.robot(robot_id)
    # Stamps are wall-clock seconds (time.time): the daemon may run on another computer, and
    # NTP keeps lab machines within milliseconds; monotonic clocks are not comparable across them.
    wall0 = time.time()
    if uses_world_process(cfg, robot):
        return _run_remote(cfg, robot, stop, duration, connect_timeout, wall0)
    driver, hub = driver_class(robot).local(cfg, robot, wall0, strict)
    try:
        driver.connect(timeout=connect_timeout)
    except DriverError as exc:
        return 1, str(exc)
    try:
        bus = _open_until(stop, cfg, robot_id)
        if bus is None:
            return 0, ""
        with bus, robot_estop_path(cfg, robot_id) as second:
            hold = driver_class(robot).holds_on_loss
            return _serve(
                cfg, robot, bus, driver, stop, duration, wall0, hub, exit_on_loss=not hold,
                estop_bus=second,
            )  # fmt: skip
    finally:
        driver.close()
        if hub is not None:
            hub.world.close()


def _run_remote(
    cfg: FleetConfig,
    robot,
    stop: threading.Event,
    duration: float,
    connect_timeout: float,
    wall0: float,
) -> tuple[int, str]:
    """A ``sim`` robot of the shared world process: the bus first (the link to the world runs
    over it), then the driver's handshake (the world's first pose sample for this robot)."""
    from drivers.base import DriverError

    remote = driver_class(robot).remote
    assert remote is not None, f"driver {robot.driver!r}: over_bus without remote"
    bus = _open_until(stop, cfg, robot.id)
    if bus is None:
        return 0, ""
    with bus, robot_estop_path(cfg, robot.id) as second:
        driver = remote(bus, cfg, robot)
        try:
            driver.connect(timeout=connect_timeout)
        except DriverError as exc:
            return 1, str(exc)
        try:
            # the world going silent (restarted, or starved of CPU) is not the end of the agent:
            # it reports link_lost, holds the robot stopped, and link_restored when it is back
            return _serve(
                cfg, robot, bus, driver, stop, duration, wall0, None, exit_on_loss=False,
                estop_bus=second,
            )  # fmt: skip
        finally:
            driver.close()


def _serve(
    cfg: FleetConfig,
    robot,
    bus: Bus,
    driver,
    stop: threading.Event,
    duration: float,
    wall0: float,
    hub: SimHub | None,
    *,
    exit_on_loss: bool = True,
    estop_bus: Bus | None = None,
) -> tuple[int, str]:
    """The agent's wall-clock loop until ``stop``, ``duration`` or (``exit_on_loss``) a lost
    link. ``estop_bus``: the e-stop's second path (``robot_estop_path``)."""
    from controller.io.ratekeeper import Ratekeeper

    if already_served(bus, "robot", robot.id, cfg.fleet.liveliness_lease, stop):
        return 1, (
            f"another agent already serves robot {robot.id} of fleet {cfg.fleet.name!r} (its "
            "liveliness token stayed on the bus past its lease): two agents would drive one "
            "robot; stop the other (fleet status names the robots present) or fix the robot ids"
        )
    skew = cfg.fleet.max_clock_skew
    # on the lab's wall clock: an operator's release older than the clocks' skew is a replay
    params = AgentParams(robot.id, cfg.fleet.name, cfg.fleet.cmd_ttl, skew, release_max_age=skew)
    # the latched e-stop first: a fresh agent is stopped ("fail closed") until it learns the
    # latch (an engaged answer, or the hub's or the controller's) or an operator releases it
    agent = Agent(bus, driver, params, latch_at_start=None, estop_bus=estop_bus)
    if not agent.sync_latch(LATCH_WAIT):  # a fresh lab: nobody knows the latch yet (normal)
        log.info("robot %s: no holder knows the e-stop yet (a fresh lab)", robot.id)
    state = agent.core.latch.state()
    log.info(
        "robot %s: agent up (%s driver%s), e-stop %s",
        robot.id,
        robot.driver,
        ", shared world process" if uses_world_process(cfg, robot) else "",
        "unknown: STOPPED until an operator's resume"
        if state is None
        else ("ENGAGED" if state.engaged else "off"),
    )
    agent.announce(time.time())
    if hub is not None:
        # its own world ran nothing while the agent waited for the bus (the daemon's start):
        # brought to the clock at once, before any command (else its poses came stamped in
        # the past, dropped as skewed, while the capped catch-up below slowly made it good)
        hub.advance_to(time.time() - wall0)
    rate = max(cfg.fleet.rate_hz, 20.0)
    rk = Ratekeeper(rate, sleep=agent.wait_for_estop)  # an e-stop ends the pause at once
    catch_up = None if hub is None else max(1, math.ceil(2.0 / (rate * hub.dt)))
    behind_told = False
    next_latch = time.monotonic() + LATCH_EVERY
    while not stop.is_set():
        rk.keep_time()
        now = time.time()
        if time.monotonic() >= next_latch:  # re-read: an e-stop missed while cut off
            agent.request_latch()
            next_latch = time.monotonic() + LATCH_EVERY
        if hub is not None:
            # a world of the agent's own: two loop periods of physics at most per iteration,
            # so the watchdog, the e-stop and the commands are served on time whatever the
            # machine; a world that cannot keep up falls behind the clock (said once)
            hub.advance_to(now - wall0, max_steps=catch_up)
            if not behind_told and now - wall0 - hub.t > BEHIND_S:
                behind_told = True
                log.warning(
                    "robot %s: its own world runs %.1f s behind the clock (this machine cannot "
                    'step every agent\'s world in real time; sim.world = "process" steps one '
                    "world for all)",
                    robot.id,
                    now - wall0 - hub.t,
                )
        agent.step(now)
        if exit_on_loss and not agent.link_ok:
            return 1, "link lost: robot stopped"
        if duration and now - wall0 >= duration:
            break
    return 0, ""


def run_agents(
    cfg: FleetConfig,
    ids: list[str],
    stop: threading.Event,
    duration: float = 0.0,
    connect_timeout: float = 60.0,
    *,
    strict: bool = False,
) -> int:
    """``fleet driver r1,r2,...``: several agents in this process, a thread each (its own
    session, driver and loop, as :func:`run_agent`); the worst exit status of them. One that
    ends stops none of the others; ``stop`` ends them all."""
    import sys

    codes: dict[str, int] = {}

    def one(rid: str) -> None:
        try:
            code, message = run_agent(cfg, rid, stop, duration, connect_timeout, strict=strict)
        except Exception as exc:  # noqa: BLE001 - one agent's bug must not take the others
            log.exception("robot %s: agent failed", rid)
            code, message = 1, f"agent failed: {exc!r}"
        codes[rid] = code
        if message:
            print(f"fleet driver {rid}: {message}", file=sys.stderr, flush=True)

    threads = [threading.Thread(target=one, args=(rid,), name=f"agent-{rid}") for rid in ids]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return max(codes.values(), default=0)
