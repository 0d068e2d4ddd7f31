"""``fleet estop`` / ``fleet resume``: the e-stop put straight to the agents, and confirmed;
and the latch's file (the controller side's only e-stop I/O besides the bus).

The ``EStop`` goes out on ``estop`` (every agent, the hub and the controller subscribe) with the
next ``epoch``: one above the greatest any holder answers (``controller.latch`` refuses a release
at or below the epoch it holds). Then every holder of the latch is asked
(``estop/state/<role>/<id>``, QueryTarget.ALL, replies read as they come so a hung daemon costs
nothing) until each known agent (the config's robots and every robot liveliness token) answers
with the new state at that epoch or above. An unconfirmed e-stop is put again every ``REPUT`` s
(it is latched: a repeat is harmless), one epoch above any holder that refused it. Nothing here
waits for the daemon.

``LatchFile``: the hub and the daemon each keep their latch in
``<log.state_dir or log.dir>/estop-<fleet>-<holder>.json`` (written to a temporary file, fsynced,
renamed over the old one, directory fsynced) and read it back at start: a restarted hub or daemon,
and a full restart, come up with the latch they left. A file that is missing or unreadable leaves
the latch unknown (stopped).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from pathlib import Path
from typing import Any

from controller import wire
from controller.config import FleetConfig

log = logging.getLogger(__name__)

EPOCH_WAIT = 0.3  # s: how long the tool gathers the holders' epochs before it puts
REPUT = 0.25  # s between repeats of an unconfirmed e-stop


def put_estop(
    bus, cfg: FleetConfig, word: str, source: str, reason: str, timeout: float
) -> dict[str, Any]:
    """Engage (``word`` "estop") or release ("resume") and wait at most ``timeout`` s for the
    confirmations. Returns the ``--json`` object (``confirmed``: every known agent did)."""
    engaged = word == "estop"
    t0 = time.monotonic()
    deadline = t0 + timeout
    pub = bus.publisher("estop")
    tokens: list[str] = []  # robot liveliness tokens, appended as the replies come
    bus.alive_ids_async("robot", tokens, timeout=min(1.0, timeout))
    # an engage goes out at once (any epoch latches, at the holder's own epoch or above); a
    # release must exceed every holder's epoch: ask them first
    epoch = 0 if engaged else held_epoch(bus, min(EPOCH_WAIT, timeout / 3)) + 1
    msg = wire.EStop(t=time.time(), engaged=engaged, source=source, reason=reason, epoch=epoch)
    while not pub.matching() and time.monotonic() < deadline:
        time.sleep(0.005)  # polling for the subscribers' declarations (a handshake)
    pub.put(msg)
    sent = time.monotonic()
    known = set(cfg.robot_ids)
    agents, holders, elapsed, epoch = _confirmations(bus, msg, known, tokens, deadline, pub, t0)
    known |= set(tokens[:])
    status = None
    for _, st in bus.query_replies(bus.key("status"), wire.FleetStatus, timeout=0.3):
        status = st
        break
    missing = sorted(known - agents)
    return {
        "command": word,
        "engaged": engaged,
        "confirmed": not missing,
        "phase": status.phase if status else None,
        "agents_confirmed": sorted(agents),
        "agents_missing": missing,
        "known_agents": sorted(known),
        "daemon_confirmed": "controller" in holders,
        "hub_confirmed": "hub" in holders,
        "elapsed_s": None if missing or elapsed is None else round(elapsed, 4),
        "sent_after_s": round(sent - t0, 4),
        "epoch": epoch,
    }


def held_epoch(bus, timeout: float) -> int:
    """The greatest epoch any holder answers within ``timeout`` s (0 when none answers)."""
    best = 0
    for _, st in bus.query_replies(bus.estop_wildcard(), wire.EStop, timeout):
        best = max(best, st.epoch)
    return best


def _confirmations(
    bus, msg: wire.EStop, config: set[str], tokens: list[str], deadline: float, pub, t0: float
):
    """Ask every latch holder until every known agent (the ``config``'s robots and the robot
    ``tokens`` seen so far, which the liveliness look-up fills meanwhile) holds ``msg``'s state
    (a release: at its epoch or above) and every other holder that answers at all (the hub, the
    daemon) holds it too, or the deadline. A holder engaged at the release's epoch
    or above refused it: it is put again one epoch above. Returns (agents that confirmed, roles
    of the other holders that did, seconds from ``t0`` to the last agent's confirmation or None,
    the greatest epoch a confirmation named)."""
    g = _Gather(msg, config, tokens, t0)
    next_put = time.monotonic() + REPUT
    while time.monotonic() < deadline and not g.done():
        left = deadline - time.monotonic()
        for key, st in bus.query_replies(bus.estop_wildcard(), wire.EStop, min(0.3, left)):
            parsed = wire.parse_key(key, bus.fleet)
            if parsed is not None and g.take(parsed, st):  # refused: put it above
                pub.put(g.msg)
                next_put = time.monotonic() + REPUT
            if g.done():
                break
        if not g.done() and time.monotonic() >= next_put:
            pub.put(g.msg)
            next_put = time.monotonic() + REPUT
        if not g.done():
            time.sleep(0.005)  # between rounds of a poll (each round is a real check)
    return g.agents, g.holders, g.elapsed, g.epoch


class _Gather:
    """The confirmations of one put, as the holders' replies come."""

    def __init__(self, msg: wire.EStop, config: set[str], tokens: list[str], t0: float) -> None:
        self.msg, self.config, self.tokens, self.t0 = msg, config, tokens, t0
        self.agents: set[str] = set()
        self.holders: set[str] = set()
        self.present: set[str] = set()  # the other holders' roles (hub, controller) that answer
        self.elapsed: float | None = None
        self.epoch = msg.epoch

    def known(self) -> set[str]:
        return self.config | set(self.tokens[:])

    def done(self) -> bool:
        return self.known() <= self.agents and self.present <= self.holders

    def take(self, parsed, st: wire.EStop) -> bool:
        """One holder's reply; True when it refused a release (``msg`` is now one above)."""
        role = parsed.parts.get("role", "")
        if role != "robot":
            self.present.add(role)
        if not self.msg.engaged and st.engaged and st.epoch >= self.msg.epoch:
            self.msg = dataclasses.replace(self.msg, epoch=st.epoch + 1)
            return True
        if st.engaged != self.msg.engaged or st.epoch < self.msg.epoch:
            return False
        self.epoch = max(self.epoch, st.epoch)
        if role == "robot":
            self.agents.add(parsed.id)
        else:
            self.holders.add(role)
        if self.elapsed is None and self.known() <= self.agents:
            self.elapsed = time.monotonic() - self.t0
        return False


class LatchFile:
    """The latch kept in one small JSON file (an ``EStop``), replaced atomically."""

    def __init__(self, cfg: FleetConfig, holder: str) -> None:
        """``holder``: "hub" or "controller" (each keeps its own file)."""
        folder = Path(cfg.log.state_dir or cfg.log.dir)
        self.path = folder / f"estop-{cfg.fleet.name}-{holder}.json"

    def load(self) -> wire.EStop | None:
        """The latch last written, or None (no file, or unreadable: logged) - unknown."""
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            log.warning("no e-stop latch file %s: the latch is unknown (stopped)", self.path)
            return None
        except OSError as exc:
            log.error("e-stop latch file %s unreadable (%s): the latch is unknown", self.path, exc)
            return None
        try:
            msg = wire.decode(wire.EStop, raw)
        except wire.WireError as exc:
            log.error("e-stop latch file %s is corrupt (%s): the latch is unknown", self.path, exc)
            return None
        return msg if isinstance(msg, wire.EStop) else None

    def save(self, msg: wire.EStop) -> None:
        """Write ``msg``: a temporary file, fsync, rename over the old one, fsync the folder."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "wb") as f:
            f.write(wire.encode(msg))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        fd = os.open(self.path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


class LatchKeeper:
    """Writes a latch to its ``LatchFile`` whenever it changed (``poll`` from a loop thread,
    never from a zenoh callback). Write errors are logged, once per kind, and retried."""

    def __init__(self, latch, file: LatchFile) -> None:
        self.latch, self.file = latch, file
        self.saved = latch.version
        self._failing = False

    def poll(self) -> bool:
        """Save if the latch changed since the last save; returns whether it wrote."""
        version, msg = self.latch.version, self.latch.state()
        if version == self.saved or msg is None:
            return False
        try:
            self.file.save(msg)
        except OSError as exc:
            if not self._failing:
                log.error("cannot keep the e-stop latch in %s: %s", self.file.path, exc)
            self._failing = True
            return False
        self._failing = False
        self.saved = version
        return True
