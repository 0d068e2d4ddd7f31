"""``fleet daemon``: the controller on the lab network, ticking on the wall clock.

Listens on the config's zenoh endpoints (robot agents and tools connect to it) or, when a
``fleet hub`` already listens there, joins the hub as a client; ticks at ``fleet.rate_hz`` with a
drift-free rate keeper, runs the mission, serves ``fleet status`` and obeys ``fleet estop``/
``resume``, and records the bus to MCAP. Returns when ``stop`` is set, after ``duration``
seconds, or when the mission ends (robots then stop by their own watchdogs after one last zero
command for everyone).

One controller per fleet (``controller.runtime.claim``): a daemon that finds another
controller's liveliness token refuses to start unless told to take over; a running one that
sees a newer controller stops commanding and exits 1 naming it.

The e-stop latch (``controller.latch``): at start, and after the loop was held up (a hung
process, SIGSTOP), the controller asks every holder (hub, agents) for the latched e-stop and
commands zero until one answers, so a restarted or resumed daemon never drives robots through an
e-stop it missed. It keeps its latch in a file (``runtime.estop.LatchFile``), read at start and
written on every change, so without a hub a restarted daemon, or a full restart, comes up with
the latch it left. Without a file it starts "fail closed": unknown (stopped) until it learns the
latch (the hub's answer, any engaged answer) or an operator releases it.

The slow plans run off the loop in the planner worker (``controller.runtime.planner``).
"""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

from controller.config import FleetConfig
from controller.io.bus import Bus, BusError
from controller.io.ratekeeper import Ratekeeper
from controller.mission.types import Mission
from controller.outcome import report
from controller.runtime.claim import ROLE, Claim, far_ahead, make_ident, wait_until_alone
from controller.runtime.estop import LatchFile, LatchKeeper
from controller.runtime.gcpause import freeze_for_real_time, release
from controller.runtime.hub import HUB_START, start_hub_process, stop_hub_process
from controller.runtime.job_record import JobRecord
from controller.runtime.node import ControllerNode
from controller.runtime.planner import PlannerWorker
from controller.runtime.recording import open_recorder, record_paths, record_ros2
from controller.runtime.ros2_graph import Ros2Graph, open_ros2_graph, publish_graph
from controller.runtime.wiring import make_estimator

log = logging.getLogger(__name__)

# s: nobody answers the latch query at start → stop waiting: the latch stays what it is (from
# the file, or unknown: stopped until an operator's release), asked again every LATCH_UNKNOWN
RING_TOPICS = ("robot_pose", "object_pose")  # read by the loop from zenoh rings (NodeInputs)
LATCH_WAIT_AT_START = 2.0
LATCH_RETRY = 0.5  # s between latch queries while one is pending
LATCH_UNKNOWN = 2.0  # s between latch queries while the latch is unknown
# s: a loop held up this long (a hung process) re-reads the latch before commanding again
GAP = 1.0
FIND_TIMEOUT = 1.0  # s: the look-up of other controllers' tokens at start
# s: a take-over waits this long for the old controller to stop (a hung one keeps its token
# until its transport lease, 10 s by default, expires)
TAKE_OVER_WAIT = 15.0
REOPEN_WAIT = 5.0  # s: the old controller's endpoint is freed when its process ends
# s a take-over waits for the old controller's own hub (a child that ends with it) to go
HUB_SETTLE = 5.0


def open_daemon_bus(cfg: FleetConfig) -> tuple[Bus, str]:
    """The daemon's session: listening on ``zenoh.listen`` as before, or, when the endpoints
    are taken (a ``fleet hub`` listens there), a client of the hub. Returns (bus, how)."""
    try:
        return Bus(cfg.zenoh, cfg.fleet.name), "listening"
    except BusError as listen_error:
        try:
            bus = _client_of_hub(cfg)
        except BusError:
            raise listen_error from None
        return bus, "joined the hub"


def _reopen(cfg: FleetConfig, stop: threading.Event) -> tuple[Bus, str, subprocess.Popen | None]:
    """The daemon's session again (``open_daemon_session``), once the controller taken over
    from is gone (it may have been the one listening on the endpoints)."""
    deadline = time.monotonic() + REOPEN_WAIT
    while True:
        try:
            return open_daemon_session(cfg)
        except BusError:
            if time.monotonic() >= deadline or stop.is_set():
                raise
            stop.wait(0.2)  # retrying an endpoint a process frees as it ends


def claim_fleet(
    cfg: FleetConfig, take_over: bool, stop: threading.Event
) -> tuple[Bus, str, Claim, subprocess.Popen | None] | int:
    """Open the daemon's session (``open_daemon_session``) and claim the fleet
    (``controller.runtime.claim``): the bus, how it joined, the claim and the hub it started
    (or None); or exit 1 when another controller runs (without ``take_over``) or would not
    stop (with it)."""
    bus, how, own_hub = open_daemon_session(cfg)
    try:
        found = bus.alive_ids(ROLE, timeout=FIND_TIMEOUT)
    except BaseException:
        bus.close()
        stop_hub_process(own_hub)
        raise
    claim = Claim(make_ident(int(time.time() * 1e3), found), found)
    if not found:
        return bus, how, claim, own_hub
    name = cfg.fleet.name
    with bus:
        if not take_over:
            odd = [f for f in found if far_ahead(f, time.time() * 1e3)]
            print(
                f"fleet daemon: another controller of fleet {name!r} is running "
                f"({', '.join(found)}): not starting (fleet daemon --take-over replaces it)"
                + (
                    f"; {', '.join(odd)} is stamped far in the future: forged, or a clock far "
                    "off (on the open profile anyone on the port can declare a controller; the "
                    "lab profile's ACL stops that: docs/lab/safety.md)"
                    if odd
                    else ""
                ),
                file=sys.stderr,
            )
            stop_hub_process(own_hub)
            return 1
        claim.watch(bus)
        bus.declare_alive(ROLE, claim.ident)
        print(
            f"fleet daemon: taking over fleet {name!r} from {', '.join(found)} as {claim.ident}",
            file=sys.stderr,
        )
        if not wait_until_alone(claim, TAKE_OVER_WAIT, stop):
            left = sorted(claim.predecessors) or [claim.yielded_to]
            print(
                f"fleet daemon: {', '.join(left)} did not stop within {TAKE_OVER_WAIT:.0f} s: "
                "not starting (nothing was commanded)",
                file=sys.stderr,
            )
            stop_hub_process(own_hub)
            return 1
    _wait_for_its_hub_to_go(cfg, stop)
    bus, how, again = _reopen(cfg, stop)
    return bus, how, claim, own_hub or again


def _wait_for_its_hub_to_go(cfg: FleetConfig, stop: threading.Event) -> None:
    """The controller taken over from may have run the fleet's hub as its own child, which ends
    with it a moment after its token: joining that hub now would leave this daemon connected to
    nothing. Wait (at most ``HUB_SETTLE`` s) until the endpoints refuse a client (its hub is
    gone: this daemon starts its own) or keep answering (a ``fleet hub`` of its own, stays)."""
    deadline = time.monotonic() + HUB_SETTLE
    while time.monotonic() < deadline and not stop.is_set():
        try:
            probe = _client_of_hub(cfg)
        except BusError:
            return  # nobody listens: the old daemon's hub is gone
        probe.close()
        stop.wait(0.5)  # polling the endpoint while the old daemon's hub shuts down


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
        self.node.estop_latch.expect(timeout=LATCH_RETRY)
        self.next_query = mono + LATCH_RETRY

    def poll(self, mono: float) -> None:
        if self.keeper is not None:
            self.keeper.poll()
        if not self.node.estop_latch.pending:
            if not self.node.estop_latch.latch.known and mono >= self.next_query:
                self.node.estop_latch.ask(timeout=LATCH_RETRY)
                self.next_query = mono + LATCH_UNKNOWN
            return
        if self.give_up_at is not None and mono >= self.give_up_at:
            self.node.estop_latch.release()
            self.next_query = mono + LATCH_UNKNOWN
        elif mono >= self.next_query:
            self.node.estop_latch.expect(timeout=LATCH_RETRY)
            self.next_query = mono + LATCH_RETRY


class TickBudget:
    """Counts the ticks that took longer than ``fleet.tick_budget`` (the node's own stage
    timings: sample to publish) and logs when it starts and every 100th time."""

    def __init__(self, budget: float) -> None:
        self.budget = budget
        self.over = 0

    def check(self, node: ControllerNode) -> None:
        took = node.times.last_s
        if took is None or took <= self.budget:
            return
        self.over += 1
        node.counters.over_budget = self.over
        if self.over == 1 or self.over % 100 == 0:
            log.warning(
                "a control tick took %.1f ms, over its %.1f ms budget (%d so far)",
                took * 1e3,
                self.budget * 1e3,
                self.over,
            )


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


def open_estop_path(cfg: FleetConfig) -> Bus | None:
    """The e-stop's second path: a router of the daemon's own on ``zenoh.estop_listen`` (the
    hub's security applied: password dictionary, TLS, ACL), which every agent and ``fleet
    estop`` also connect to. None when not configured, or when it cannot listen there (said
    loudly: the hub is then the e-stop's only path)."""
    if not cfg.zenoh.estop_listen:
        return None
    where = list(cfg.zenoh.estop_listen)
    try:
        return Bus(cfg.zenoh, cfg.fleet.name, mode="router", listen=where, connect=[])
    except BusError as exc:
        log.error(
            "zenoh.estop_listen %s: cannot listen (%s): the e-stop's only path is the hub",
            where,
            exc,
        )
        return None


def _second_text(cfg: FleetConfig, second: Bus | None) -> str:
    return "" if second is None else f"; e-stop also on {list(cfg.zenoh.estop_listen)}"


def _close(part: Bus | Ros2Graph | None) -> None:
    if part is not None:
        part.close()


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
    planners: PlannerWorker | None = None,
    take_over: bool = False,
) -> int:
    """The lab loop. Exit status: 0 stopped or done, 1 the mission failed, another controller
    runs (without ``take_over``) or a newer one took over. ``viz``: serve the recorded
    messages live to Foxglove on 127.0.0.1. ``planners``: the worker ``mission`` plans
    through, off the loop (closed at the end)."""
    claimed = claim_fleet(cfg, take_over, stop)
    if isinstance(claimed, int):
        if planners is not None:
            planners.close()
        return claimed
    bus, how, claim, own_hub = claimed
    second = open_estop_path(cfg)  # after the claim: a second daemon never listens there
    recorder = open_recorder(cfg, out, f"daemon/{mission_kind}", viz=viz, who="fleet daemon")
    graph = open_ros2_graph(cfg)
    status = 0
    health = ""
    outcome: dict | None = None
    try:
        with bus:
            claim.watch(bus)
            # the poses reach the recorder from the loop's rings (a robot's flood unread); the
            # e-stops from both paths, once each
            record_paths(bus, second, recorder, RING_TOPICS)
            record_ros2(bus, cfg, recorder)  # ROS 2 robots' own topics too
            rk = Ratekeeper(cfg.fleet.rate_hz)
            # the latch it left (without a hub it is the keeper; with one it learns from it too)
            file = LatchFile(cfg, "controller")
            node = ControllerNode(
                cfg,
                bus,
                mission,
                make_estimator(cfg),
                # the loop's health beside the drops: ticks that started late, periods skipped
                extra_drops=lambda: {
                    **recorder.drops(),
                    "late_ticks": rk.lagged,
                    "skipped_ticks": rk.skipped,
                },
                clock=time.monotonic,
                planners=planners,
                ident=claim.ident,
                latch_at_start=file.load_kept("controller/main"),
                estop_bus=second,
                rings=True,
                pose_tap=recorder.on_sample,
            )
            # the wall clock: see the latch
            node.estop_latch.release_max_age = cfg.fleet.max_clock_skew
            latch = LatchWatch(node, LatchKeeper(node.estop_latch.latch, file))
            latch.start(time.monotonic(), LATCH_WAIT_AT_START)
            print(
                f"fleet daemon: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)} ({how}"
                f"{_second_text(cfg, second)}), "
                f"{cfg.fleet.rate_hz} Hz, log {recorder.location}, controller {claim.ident}",
                file=sys.stderr,
            )
            gc_watch = freeze_for_real_time()  # start-up's objects never walked again
            t0 = time.time()
            job = JobRecord(cfg, t0)  # its outcome, printed at the end
            stopped = "interrupted"
            budget = TickBudget(cfg.fleet.budget)
            lag_reported = 0
            last = time.monotonic()
            while not stop.is_set():
                rk.keep_time()
                mono = time.monotonic()
                if mono - last > GAP:
                    log.warning("the loop was held up %.1f s: re-reading the e-stop", mono - last)
                    latch.start(mono, None)
                    claim.check(bus)  # taken over meanwhile?
                last = mono
                if claim.yielded.is_set():
                    status = 1
                    stopped = f"controller {claim.yielded_to} took over"
                    print(
                        f"fleet daemon: controller {claim.yielded_to} took over: stopped "
                        "commanding",
                        file=sys.stderr,
                    )
                    break
                latch.poll(mono)
                now = time.time()  # wall clock: pose stamps come from other computers
                result = node.tick(now)
                publish_graph(graph, now, node)  # the fleet on the ROS graph, if configured
                recorder.kick()  # the tick's samples written while the loop sleeps
                job.tick(now, result)
                budget.check(node)
                if rk.lagged > lag_reported:
                    lag_reported = rk.lagged
                    log.warning(
                        "control loop lag %.1f ms (%d late ticks)", rk.last_lag * 1e3, rk.lagged
                    )
                if result.done or result.failed:
                    status = 1 if result.failed else 0
                    log_end(job)
                    break
                if duration and now - t0 >= duration:
                    stopped = f"--duration {duration:g} s"
                    break
            release(gc_watch)
            node.winding_down = True  # robots leaving from now on are the end, not news
            if not claim.yielded.is_set():
                node.hold(time.time())
            latch.poll(time.monotonic())  # the last change of the latch written too
            outcome = job.summary(
                mission,
                stopped,
                time.time(),
                log=str(recorder.location),
                plan_latency_s={} if planners is None else planners.summary(),
                # write errors (full disk...) and messages not logged, so far
                log_errors=recorder.drops()["log_errors"],
                log_dropped=recorder.drops()["log_dropped"],
            )
            ticks = node.status().tick_ms
            health = (
                f"; {node.counters.ticks} ticks, {rk.lagged} late, {budget.over} over the "
                f"{cfg.fleet.budget * 1e3:.0f} ms budget (p50 {ticks.get('p50', 0):.1f} ms, "
                f"p99 {ticks.get('p99', 0):.1f} ms)"
            )
    finally:
        recorder.close()
        _close(graph)
        _close(second)
        stop_hub_process(own_hub)
        if planners is not None:
            planners.close()
    print(
        f"fleet daemon: stopped; {recorder.written} messages in {recorder.location}{health}"
        f"{_log_health(recorder)}",
        file=sys.stderr,
    )
    if outcome is not None:
        print(report(outcome), flush=True)  # the verdict, the figures, the next steps
    return status


def _log_health(recorder) -> str:
    """The log's losses for the daemon's last line ("" when none)."""
    lost = recorder.drops()
    if not (lost["log_errors"] or lost["log_dropped"]):
        return ""
    return (
        f"; LOG INCOMPLETE: {lost['log_errors']} write errors, {lost['log_dropped']} "
        f"messages not logged ({len(recorder.segments)} segments)"
    )


def log_end(job: JobRecord) -> None:
    """The mission's end in the daemon's log: done, or failed naming the phase it failed in,
    the reason, when (s since the job's start) and the failure's detail."""
    fail = job.failure
    if fail is None:
        log.info("mission done in phase %s", job.phases[-1]["phase"] if job.phases else "done")
        return
    log.error(
        "mission failed in phase %s: %s at %.1f s: %s",
        job.phase,
        fail["reason"],
        fail["t"] - job.t0,
        fail["detail"] or "(no detail)",
    )
