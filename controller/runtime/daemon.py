"""``fleet daemon``: the controller on the lab network, ticking on the wall clock.

Listens on the config's zenoh endpoints (robot agents and tools connect to it) or, when a
``fleet hub`` already listens there, joins the hub as a client; ticks at ``fleet.rate_hz`` with a
drift-free rate keeper, runs the mission, serves ``fleet status`` and obeys ``fleet estop``/
``resume``, and records the bus to MCAP. Returns when ``stop`` is set, after ``duration``
seconds, or when the mission ends (robots then stop by their own watchdogs after one last zero
command for everyone).

The e-stop latch (``controller.latch``): at start, and after the loop was held up (a hung
process, SIGSTOP), the controller asks every holder (hub, agents) for the latched e-stop and
commands zero until one answers, so a restarted or resumed daemon never drives robots through an
e-stop it missed. It keeps its latch in a file (``runtime.estop.LatchFile``), read at start and
written on every change, so without a hub a restarted daemon, or a full restart, comes up with
the latch it left. Without a file it starts "fail closed": unknown (stopped) until it learns the
latch (the hub's answer, any engaged answer) or an operator releases it.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

from controller import wire
from controller.config import FleetConfig
from controller.io.bus import Bus, BusError
from controller.io.ratekeeper import Ratekeeper
from controller.mission.types import Mission
from controller.runtime.estop import LatchFile, LatchKeeper
from controller.runtime.hub import HUB_START, start_hub_process, stop_hub_process
from controller.runtime.node import ControllerNode
from controller.runtime.recording import open_recorder
from controller.runtime.wiring import make_estimator

log = logging.getLogger(__name__)

# s: nobody answers the latch query at start → stop waiting: the latch stays what it is (from
# the file, or unknown: stopped until an operator's release), asked again every LATCH_UNKNOWN
LATCH_WAIT_AT_START = 2.0
LATCH_RETRY = 0.5  # s between latch queries while one is pending
LATCH_UNKNOWN = 2.0  # s between latch queries while the latch is unknown
# s: a loop held up this long (a hung process) re-reads the latch before commanding again
GAP = 1.0


def open_daemon_bus(cfg: FleetConfig) -> tuple[Bus, str]:
    """The daemon's session: listening on ``zenoh.listen`` as before, or, when the endpoints
    are taken (a ``fleet hub`` listens there), a client of the hub. Returns (bus, how)."""
    try:
        return Bus(cfg.zenoh, cfg.fleet.name), "listening"
    except BusError as listen_error:
        try:
            bus = Bus(
                cfg.zenoh,
                cfg.fleet.name,
                mode="client",
                listen=[],
                connect=list(cfg.zenoh.listen),
                lease_s=cfg.fleet.liveliness_lease,
            )
        except BusError:
            raise listen_error from None
        return bus, "joined the hub"


class LatchWatch:
    """When the controller must (re-)read the latched e-stop, and for how long it waits; with
    a ``keeper``, the latch written to its file on every change."""

    def __init__(self, node: ControllerNode, keeper: LatchKeeper | None = None) -> None:
        self.node = node
        self.keeper = keeper
        self.give_up_at: float | None = None  # None: wait as long as it takes
        self.next_query = 0.0

    def start(self, mono: float, give_up_after: float | None) -> None:
        self.give_up_at = None if give_up_after is None else mono + give_up_after
        self.node.expect_latch(timeout=LATCH_RETRY)
        self.next_query = mono + LATCH_RETRY

    def poll(self, mono: float) -> None:
        if self.keeper is not None:
            self.keeper.poll()
        if not self.node.latch_pending:
            if not self.node.latch.known and mono >= self.next_query:
                self.node.ask_latch(timeout=LATCH_RETRY)
                self.next_query = mono + LATCH_UNKNOWN
            return
        if self.give_up_at is not None and mono >= self.give_up_at:
            self.node.release_latch()
            self.next_query = mono + LATCH_UNKNOWN
        elif mono >= self.next_query:
            self.node.expect_latch(timeout=LATCH_RETRY)
            self.next_query = mono + LATCH_RETRY


def open_daemon_session(cfg: FleetConfig) -> tuple[Bus, str, subprocess.Popen | None]:
    """The daemon's session: a client of the ``fleet hub`` (or world) already listening on
    ``zenoh.listen``; else a client of a hub it starts itself as a child process, so that
    ``fleet estop`` still reaches the agents while the daemon is hung (its own listening session
    would hang with it); else, if that hub does not come up, listening itself as before.
    Returns (bus, how, the hub it started or None)."""
    try:
        return _client_of_hub(cfg), "joined the hub", None
    except BusError:
        pass
    child = start_hub_process(cfg)
    deadline = time.monotonic() + HUB_START
    while child is not None and child.poll() is None and time.monotonic() < deadline:
        try:
            return _client_of_hub(cfg), "joined the hub it started", child
        except BusError:
            time.sleep(0.1)  # polling for the child hub to listen (a handshake, retried)
    if child is not None:
        log.error("the hub this daemon started did not come up: listening itself")
        stop_hub_process(child)
    bus, how = open_daemon_bus(cfg)
    return bus, how, None


def _client_of_hub(cfg: FleetConfig) -> Bus:
    return Bus(
        cfg.zenoh,
        cfg.fleet.name,
        mode="client",
        listen=[],
        connect=list(cfg.zenoh.listen),
        lease_s=cfg.fleet.liveliness_lease,
    )


def run_daemon(
    cfg: FleetConfig,
    mission: Mission,
    mission_kind: str,
    out: Path,
    stop: threading.Event,
    duration: float = 0.0,
    viz: bool = False,
) -> int:
    """The lab loop. Exit status: 0 stopped or done, 1 the mission failed. ``viz``: serve the
    recorded messages live to Foxglove on 127.0.0.1."""
    recorder = open_recorder(cfg, out, f"daemon/{mission_kind}", viz=viz, who="fleet daemon")
    status = 0
    own_hub = None
    try:
        bus, how, own_hub = open_daemon_session(cfg)
        with bus:
            bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample)
            # the latch it left (without a hub it is the keeper; with one it learns from it too)
            file = LatchFile(cfg, "controller")
            node = ControllerNode(
                cfg,
                bus,
                mission,
                make_estimator(cfg),
                extra_drops=recorder.drops,
                clock=time.monotonic,
                latch_at_start=file.load(),
            )
            latch = LatchWatch(node, LatchKeeper(node.latch, file))
            latch.start(time.monotonic(), LATCH_WAIT_AT_START)
            rk = Ratekeeper(cfg.fleet.rate_hz)
            print(
                f"fleet daemon: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)} ({how}), "
                f"{cfg.fleet.rate_hz} Hz, log {recorder.location}",
                file=sys.stderr,
            )
            t0 = time.time()
            lag_reported = 0
            last = time.monotonic()
            while not stop.is_set():
                rk.keep_time()
                mono = time.monotonic()
                if mono - last > GAP:
                    log.warning("the loop was held up %.1f s: re-reading the e-stop", mono - last)
                    latch.start(mono, None)
                last = mono
                latch.poll(mono)
                now = time.time()  # wall clock: pose stamps come from other computers
                result = node.tick(now)
                if rk.lagged > lag_reported:
                    lag_reported = rk.lagged
                    log.warning(
                        "control loop lag %.1f ms (%d late ticks)", rk.last_lag * 1e3, rk.lagged
                    )
                if result.done or result.failed:
                    status = 1 if result.failed else 0
                    log.info(
                        "mission %s in phase %s",
                        "failed" if result.failed else "done",
                        result.phase,
                    )
                    break
                if duration and now - t0 >= duration:
                    break
            node.hold(time.time())
            latch.poll(time.monotonic())  # the last change of the latch written too
    finally:
        recorder.close()
        stop_hub_process(own_hub)
    print(
        f"fleet daemon: stopped; {recorder.written} messages in {recorder.location}",
        file=sys.stderr,
    )
    return status
