"""``fleet hub``: the fleet's meeting point on the lab network, and the e-stop's keeper.

A zenoh session in router mode listening on the config's ``zenoh.listen`` endpoints: agents,
the daemon (which then joins as a client instead of listening) and the tools all connect to it,
so an agent still hears ``fleet estop`` when the daemon is hung or dead. It holds the latched
e-stop (``controller.latch``): it obeys operators on ``estop`` and answers latch queries on
``estop/state/hub/main`` (agents and the controller answer the same query with their own latch,
so any one survivor suffices). It keeps the latch in a file (``runtime.estop.LatchFile``) and
reads it back at start: a restarted hub, or a full restart, comes up with the latch it left
(without the file: unknown, stopped, until an operator's release or an engaged answer). Every few
seconds it asks the other holders too: an engaged answer at its epoch or above engages it.
"""

from __future__ import annotations

import ctypes
import logging
import signal
import subprocess
import sys
import threading
import time

from controller import wire
from controller.config import FleetConfig
from controller.io.bus import Bus, Inbox, Received
from controller.latch import Latch, note_latch, role_of
from controller.runtime.estop import LatchFile, LatchKeeper

log = logging.getLogger(__name__)

RELEARN_EVERY = 2.0  # s between the hub's own latch queries
KEEP_EVERY = 0.05  # s between checks that the latch changed (then it is written to its file)


class _Answers:
    """Where the other holders' latch answers go (zenoh's thread): into the hub's latch."""

    def __init__(self, latch: Latch, own_key: str, fleet: str) -> None:
        self.latch, self.own_key, self.fleet = latch, own_key, fleet

    def put(self, item: Received) -> None:
        if item.key != self.own_key:
            role = role_of(item.key, self.fleet)
            note_latch("hub", self.latch.answers([(role, item.msg)]))


def run_hub(cfg: FleetConfig, stop: threading.Event, duration: float = 0.0) -> int:
    """Serve until ``stop`` (or ``duration`` s). Exit 0; a BusError (endpoints taken) → 1."""
    file = LatchFile(cfg, "hub")
    latch = Latch("hub/main", file.load_kept("hub/main"))
    keeper = LatchKeeper(latch, file)
    with Bus(
        cfg.zenoh, cfg.fleet.name, mode="router", listen=list(cfg.zenoh.listen), connect=[]
    ) as bus:
        bus.subscribe(
            bus.key("estop"),
            wire.EStop,
            Inbox(maxsize=1),
            # an operator's release stamped beyond the clocks' skew from its arrival: a replay
            on_message=lambda r: note_latch(
                "hub", latch.operator(r.msg, r.recv_time, cfg.fleet.max_clock_skew)
            ),
            lossless=True,  # every e-stop reaches the latch, whatever floods the key
        )
        own = bus.serve_estop("hub", "main", latch.answer)
        answers = _Answers(latch, own, cfg.fleet.name)
        held = latch.state()
        print(
            f"fleet hub: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)}, e-stop "
            f"{'unknown (stopped)' if held is None else _describe(held)} ({file.path})",
            file=sys.stderr,
            flush=True,
        )
        t0 = time.monotonic()
        next_query = t0
        while not stop.is_set():
            if time.monotonic() >= next_query:
                bus.query_async(bus.estop_wildcard(), wire.EStop, answers, timeout=1.0)
                next_query = time.monotonic() + RELEARN_EVERY
            keeper.poll()
            if duration and time.monotonic() - t0 >= duration:
                break
            stop.wait(KEEP_EVERY)
        keeper.poll()
    print("fleet hub: stopped", file=sys.stderr)
    return 0


def _describe(msg: wire.EStop) -> str:
    return f"{'ENGAGED' if msg.engaged else 'released'} (epoch {msg.epoch}, by {msg.source})"


HUB_START = 20.0  # s a daemon waits for the hub it started to listen


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """PR_SET_PDEATHSIG: the child hub gets SIGTERM when the daemon that started it dies."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)
    except OSError:
        pass  # not Linux: the daemon still stops it when it ends normally


def start_hub_process(cfg: FleetConfig) -> subprocess.Popen | None:
    """``fleet hub`` on the daemon's config as a child process of its own session (a SIGSTOP or
    a terminal's Ctrl-Z to the daemon does not reach it; it ends with the daemon). None when the
    config has no file to hand it (a config built in-process)."""
    if not cfg.source:
        return None
    argv = [sys.executable, "-m", "controller.cli", "hub", "--config", str(cfg.source)]
    try:
        return subprocess.Popen(  # noqa: S603 - our own CLI, no shell
            argv, stdin=subprocess.DEVNULL, start_new_session=True, preexec_fn=_die_with_parent
        )
    except OSError as exc:
        log.error("cannot start a hub: %s", exc)
        return None


def stop_hub_process(proc: subprocess.Popen | None) -> None:
    """End a hub started by ``start_hub_process`` (SIGTERM, then SIGKILL after 10 s)."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
