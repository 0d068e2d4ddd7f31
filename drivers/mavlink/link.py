"""MAVLink links: one pymavlink connection per url, shared by every vehicle behind it.

A ``udpin`` connection sends every packet to every peer it has seen, so several robots on one
port are addressed by target system and their messages are filed by source system
(NOTES.md).
"""

from __future__ import annotations

import logging
import os
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

os.environ["MAVLINK20"] = "1"  # before pymavlink picks its dialect: MAVLink 2 messages needed

from pymavlink import mavutil  # noqa: E402

from drivers.base import DriverError  # noqa: E402

AUTOPILOT_COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1
GCS_COMPONENT = 190  # MAV_COMP_ID_MISSIONPLANNER
MAX_DATAGRAMS_PER_PUMP = 4096
TCP_RECONNECT_EVERY = 1.0  # s between attempts to reopen a ``tcp:`` link the vehicle closed

log = logging.getLogger(__name__)


def mavutil_v2() -> Any:
    """pymavlink's mavutil with a MAVLink 2 dialect (re-selected if imported earlier without)."""
    if getattr(mavutil.mavlink, "WIRE_PROTOCOL_VERSION", "") != "2.0":
        os.environ["MAVLINK20"] = "1"
        mavutil.set_dialect("ardupilotmega")
    return mavutil


def _open_connection(url: str, source_system: int) -> Any:
    """A pymavlink connection for a url (``serial:DEV[:BAUD]`` is split into device + baud)."""
    mu = mavutil_v2()
    if url.startswith("serial:"):
        rest = url[len("serial:") :]
        dev, _, baud = rest.rpartition(":")
        if not dev or not baud.isdigit():
            dev, baud = rest, "57600"
        return mu.mavlink_connection(
            dev, baud=int(baud), source_system=source_system, source_component=GCS_COMPONENT
        )
    if not url.startswith(("udpin:", "udpout:", "tcp:", "tcpin:", "udp:")):
        raise DriverError(f"unsupported MAVLink url {url!r} (udpin:, udpout:, tcp:, serial:)")
    return mu.mavlink_connection(url, source_system=source_system, source_component=GCS_COMPONENT)


class MavLink:
    """One MAVLink connection shared by the drivers of several systems (thread-safe).

    ``pump`` reads everything available without blocking and files each message under its
    source system id; ``take`` hands a system its messages; ``send_to`` sends a message to one
    system only (on ``udpin``: to the address that system's packets came from).
    """

    def __init__(self, url: str, source_system: int):
        self.url = url
        self.conn = _open_connection(url, source_system)
        self.routed = url.startswith(("udpin:", "udp:"))
        self._lock = threading.Lock()
        self._inbox: dict[int, deque[Any]] = {}
        self._addr: dict[int, tuple[str, int]] = {}
        self._ticks: dict[int, Callable[[bool], None]] = {}
        self.unknown_sources = 0  # messages from systems nobody registered (dropped)
        self.refs = 0
        # ``tcp:``: when the vehicle closed the connection (monotonic s; None: open). pymavlink
        # would print on every read of the closed socket, which select reports readable forever
        self.closed_at: float | None = None
        self._next_reconnect = 0.0
        if url.startswith("tcp:"):
            self.conn.handle_eof = self._on_closed
            self.conn.handle_disconnect = self._on_closed

    def register(self, system_id: int, tick: Callable[[bool], None]) -> None:
        """File messages from ``system_id``; ``tick(blocking)`` is called on every ``service``."""
        with self._lock:
            self._inbox.setdefault(system_id, deque(maxlen=8192))
            self._ticks[system_id] = tick

    def unregister(self, system_id: int) -> None:
        with self._lock:
            self._inbox.pop(system_id, None)
            self._addr.pop(system_id, None)
            self._ticks.pop(system_id, None)

    def service(self, caller: int) -> None:
        """Pump, then let every registered driver handle its messages and send its keepalives
        (so robots sharing the link keep their heartbeats while one of them is busy, e.g. in a
        handshake). Other drivers are ticked only if their lock is free (no lock-order cycle)."""
        self.pump()
        with self._lock:
            ticks = list(self._ticks.items())
        for sysid, tick in ticks:
            tick(sysid == caller)

    def knows_address(self, system_id: int) -> bool:
        return not self.routed or system_id in self._addr

    def fileno(self) -> int:
        return self.conn.fd if self.conn.fd is not None else self.conn.port.fileno()

    def _on_closed(self) -> None:
        if self.closed_at is None:
            self.closed_at = time.monotonic()
            self._next_reconnect = self.closed_at + TCP_RECONNECT_EVERY
            log.warning("%s: the vehicle closed the connection; reconnecting every %g s",
                        self.url, TCP_RECONNECT_EVERY)  # fmt: skip

    def _reconnect(self) -> None:
        """One attempt to reopen a closed ``tcp:`` link (a restarted vehicle listens again)."""
        now = time.monotonic()
        if now < self._next_reconnect:
            return
        self._next_reconnect = now + TCP_RECONNECT_EVERY
        try:
            sock = socket.create_connection(self.conn.destination_addr, timeout=0.2)
        except OSError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        old, self.conn.port = self.conn.port, sock
        self.conn.fd = sock.fileno()
        try:
            old.close()
        except (OSError, AttributeError):
            pass
        self.closed_at = None
        log.info("%s: reconnected", self.url)

    def wait(self, seconds: float) -> None:
        """Block until data arrives or ``seconds`` (real time) pass."""
        if seconds <= 0:
            return
        if self.closed_at is not None:
            time.sleep(seconds)  # a closed socket is readable forever
            return
        try:
            select.select([self.fileno()], [], [], seconds)
        except (OSError, ValueError):
            time.sleep(seconds)

    def pump(self) -> None:
        """Read every available message (bounded, non-blocking) into the per-system inboxes."""
        with self._lock:
            if self.routed:
                sock = self.conn.port
                for _ in range(MAX_DATAGRAMS_PER_PUMP):
                    try:
                        data, addr = sock.recvfrom(65535)
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:
                        break
                    msgs = self.conn.mav.parse_buffer(data) or []
                    for m in msgs:
                        self._file(m, addr)
            else:
                if self.closed_at is not None:
                    self._reconnect()
                    if self.closed_at is not None:
                        return
                for _ in range(MAX_DATAGRAMS_PER_PUMP):
                    try:
                        m = self.conn.recv_msg()
                    except OSError:
                        break
                    if m is None or self.closed_at is not None:
                        break
                    self._file(m, None)

    def _file(self, m: Any, addr: tuple[str, int] | None) -> None:
        if m.get_type() == "BAD_DATA":
            return
        src = m.get_srcSystem()
        box = self._inbox.get(src)
        if box is None:
            self.unknown_sources += 1
            return
        if addr is not None and m.get_srcComponent() == AUTOPILOT_COMPONENT:
            self._addr[src] = addr
        elif addr is not None and src not in self._addr:
            self._addr[src] = addr
        box.append(m)

    def take(self, system_id: int) -> list[Any]:
        """The messages from ``system_id`` received since the last call."""
        with self._lock:
            box = self._inbox.get(system_id)
            if not box:
                return []
            out = list(box)
            box.clear()
            return out

    def send_to(self, system_id: int, build: Callable[[Any], Any], source_system: int) -> bool:
        """Pack ``build(mav)`` as ``source_system`` and send it to ``system_id`` only.

        Returns False when a routed link does not know that system's address yet.
        """
        with self._lock:
            mav = self.conn.mav
            mav.srcSystem = source_system
            msg = build(mav)
            buf = msg.pack(mav)
            mav.seq = (mav.seq + 1) % 256
            mav.total_packets_sent += 1
            mav.total_bytes_sent += len(buf)
            if self.routed:
                addr = self._addr.get(system_id)
                if addr is None:
                    return False
                try:
                    self.conn.port.sendto(buf, addr)
                except OSError:
                    return False
                return True
            try:
                self.conn.write(buf)
            except OSError:
                return False
            return True

    def close(self) -> None:
        with self._lock:
            try:
                self.conn.close()
            except OSError:
                pass


class LinkPool:
    """The MAVLink connections of a process, one per url, shared and reference-counted."""

    def __init__(self) -> None:
        self._links: dict[str, MavLink] = {}
        self._lock = threading.Lock()

    def acquire(self, url: str, source_system: int) -> MavLink:
        with self._lock:
            link = self._links.get(url)
            if link is None:
                link = MavLink(url, source_system)
                self._links[url] = link
            link.refs += 1
            return link

    def release(self, link: MavLink) -> None:
        with self._lock:
            link.refs -= 1
            if link.refs <= 0 and self._links.get(link.url) is link:
                del self._links[link.url]
                link.close()
