"""The bus: one zenoh session per process role, built from the ``[zenoh]`` config section.

I/O edge only (the planning core never imports this). Publishers encode with ``controller.wire``;
subscriber callbacks run on zenoh's thread and only decode and enqueue into an ``Inbox`` (a bad
payload is counted and logged once per burst, never raised). Liveliness tokens mark presence;
a queryable serves the fleet status.

Zenoh facts this relies on (NOTES.md): a session that is not closed hangs the process at exit,
so ``Bus`` is a context manager and every test closes it; a channel subscriber you keep no
reference to is silently undeclared, so the bus keeps every handle it creates.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from controller import wire
from controller.config import ConfigError, ZenohIdentity, ZenohSection

log = logging.getLogger(__name__)

#: bytes: a payload larger than this is dropped unread (counted): no message of ours comes close
MAX_PAYLOAD_BYTES = 4 * 1024 * 1024


def _file(path: str, key: str) -> str:
    """A file the session needs, or a ConfigError naming its config key (exit 2)."""
    if not Path(path).is_file():
        raise ConfigError("", key, f"no such file: {path}")
    return path


def _insert(conf: zenoh.Config, key: str, value: Any, cfg_key: str, json5: bool = False) -> None:
    """``value`` as JSON (or, ``json5``, already JSON5 text) at ``key``; ConfigError if refused."""
    try:
        conf.insert_json5(key, value if json5 else json.dumps(value))
    except zenoh.ZError as exc:
        raise ConfigError("", cfg_key, f"zenoh refused {key}: {exc}") from exc


def section_identity(section: ZenohSection) -> ZenohIdentity:
    """The ``[zenoh]`` identity (controller, recorder, tools) from the section alone."""
    tls = section.tls
    return ZenohIdentity(
        "zenoh",
        section.user,
        section.password,
        section.password_file,
        tls.certificate if tls else "",
        tls.private_key if tls else "",
    )


def _password(ident: ZenohIdentity) -> str:
    prefix = "zenoh_" if ident.path != "zenoh" else ""
    if ident.password:
        return ident.password
    path = _file(ident.password_file, f"{ident.path}.{prefix}password_file")
    return Path(path).read_text(encoding="utf-8").strip()


def _is_loopback(endpoint: str) -> bool:
    """Whether a zenoh endpoint (``proto/host:port``) listens on loopback only."""
    addr = endpoint.split("/", 1)[-1].split("#", 1)[0]
    host = addr.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _apply_security(
    conf: zenoh.Config, section: ZenohSection, ident: ZenohIdentity, listening: bool
) -> None:
    """Authentication, TLS and access control (README "In the lab: secure profile")."""
    prefix = "zenoh_" if ident.path != "zenoh" else ""
    if ident.user:
        _insert(conf, "transport/auth/usrpwd/user", ident.user, f"{ident.path}.{prefix}user")
        _insert(
            conf,
            "transport/auth/usrpwd/password",
            _password(ident),
            f"{ident.path}.{prefix}password",
        )
    if listening and section.auth_dictionary:
        path = _file(section.auth_dictionary, "zenoh.auth_dictionary")
        _insert(conf, "transport/auth/usrpwd/dictionary_file", path, "zenoh.auth_dictionary")
    tls = section.tls
    if tls is not None:
        tk = "transport/link/tls/"
        _insert(conf, "transport/link/protocols", ["tls"], "zenoh.tls")
        ca = _file(tls.root_ca, "zenoh.tls.root_ca")
        _insert(conf, tk + "root_ca_certificate", ca, "zenoh.tls.root_ca")
        if listening:
            cert = _file(tls.certificate, "zenoh.tls.certificate")
            key = _file(tls.private_key, "zenoh.tls.private_key")
            _insert(conf, tk + "listen_certificate", cert, "zenoh.tls.certificate")
            _insert(conf, tk + "listen_private_key", key, "zenoh.tls.private_key")
        if tls.mtls:
            _insert(conf, tk + "enable_mtls", True, "zenoh.tls.mtls")
            ck = "zenoh.tls." if ident.path == "zenoh" else f"{ident.path}.zenoh_"
            if not ident.certificate:
                raise ConfigError("", ck + "certificate", "mutual TLS needs this party's own")
            cert = _file(ident.certificate, ck + "certificate")
            key = _file(ident.private_key, ck + "private_key")
            _insert(conf, tk + "connect_certificate", cert, ck + "certificate")
            _insert(conf, tk + "connect_private_key", key, ck + "private_key")
    if listening and (section.acl_block or section.acl):
        block = section.acl_block
        if not block:
            block = Path(_file(section.acl, "zenoh.acl")).read_text(encoding="utf-8")
        _insert(conf, "access_control", block, "zenoh.acl", json5=True)


def zenoh_config(
    section: ZenohSection,
    *,
    mode: str | None = None,
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    lease_s: float | None = None,
    identity: ZenohIdentity | None = None,
) -> zenoh.Config:
    """A zenoh Config from the ``[zenoh]`` section, with per-role overrides: every session of
    every role is built here.

    ``zenoh.config_file`` (JSON5) is the base, our settings go over it. Multicast and gossip
    scouting follow the section (off by default): endpoints are explicit. ``identity`` is who
    the session authenticates as (default: the ``[zenoh]`` user; a robot agent passes its own,
    ``FleetConfig.zenoh_identity``). A session that listens also gets the hub's side: the
    password dictionary, its TLS certificate and the access-control block. A file that is
    missing raises ConfigError naming its key. A non-loopback listen endpoint on a hub that
    checks nobody (no dictionary, no mutual TLS) logs one loud warning.
    """
    if section.config_file:
        path = _file(section.config_file, "zenoh.config_file")
        try:
            conf = zenoh.Config.from_file(path)
        except zenoh.ZError as exc:
            raise ConfigError("", "zenoh.config_file", f"zenoh refused {path}: {exc}") from exc
    else:
        conf = zenoh.Config()
    here = list(section.listen if listen is None else listen)
    conf.insert_json5("mode", json.dumps(mode or section.mode))
    conf.insert_json5("listen/endpoints", json.dumps(here))
    conf.insert_json5(
        "connect/endpoints", json.dumps(list(section.connect if connect is None else connect))
    )
    conf.insert_json5("scouting/multicast/enabled", json.dumps(section.multicast_scouting))
    conf.insert_json5("scouting/gossip/enabled", json.dumps(section.gossip_scouting))
    if lease_s is not None:
        conf.insert_json5("transport/link/tx/lease", json.dumps(int(lease_s * 1000)))
        conf.insert_json5("transport/link/tx/keep_alive", json.dumps(4))
    ident = identity if identity is not None else section_identity(section)
    _apply_security(conf, section, ident, listening=bool(here))
    exposed = [ep for ep in here if not _is_loopback(ep)]
    if exposed and not section.secured:
        log.warning(
            "INSECURE: zenoh listens on %s without authentication: anyone who reaches it can "
            "command every robot and release the e-stop (set zenoh.auth_dictionary and "
            "zenoh.acl, README 'In the lab: secure profile')",
            ", ".join(exposed),
        )
    return conf


_EVERY_REPLY = zenoh.ConsolidationMode.NONE  # queries: every reply, none merged by key


@dataclass(frozen=True)
class Received:
    """One decoded sample: receive time (s, ``time.time()``), key and message."""

    recv_time: float
    key: str
    msg: wire.Message


class BusError(ConnectionError):
    """The zenoh session could not be opened (e.g. a client found nothing to connect to)."""


class DecodeStats:
    """Counts payloads that did not decode, per key; logs the first of each burst."""

    def __init__(self, quiet_after: float = 5.0) -> None:
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}
        self._last_logged: dict[str, float] = {}
        self._quiet_after = quiet_after

    def bad(self, key: str, err: Exception) -> None:
        now = time.monotonic()
        with self._lock:
            self.counts[key] = self.counts.get(key, 0) + 1
            last = self._last_logged.get(key)
            if last is None or now - last > self._quiet_after:
                self._last_logged[key] = now
                n = self.counts[key]
                log.warning("dropped a bad payload on %s (%d so far): %s", key, n, err)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self.counts.values())


def decode_payload(
    fleet: str,
    key: str,
    payload: bytes,
    msg_type: type[wire.Message] | None,
    stats: DecodeStats,
) -> wire.Message | None:
    """A subscriber's decode step: the message, or None after counting a bad payload (too
    large, not JSON, wrong fields or types, NaN/inf, out-of-range magnitudes, no registered
    type for ``key``). Never raises."""
    try:
        if len(payload) > MAX_PAYLOAD_BYTES:
            raise wire.WireError(f"payload of {len(payload)} bytes > {MAX_PAYLOAD_BYTES}")
        tp = msg_type
        if tp is None:
            topic = wire.topic_for_key(fleet, key)
            if topic is None or topic.msg is wire.Message:
                raise wire.WireError(f"no message type registered for {key}")
            tp = topic.msg
        return wire.decode(tp, payload)
    except Exception as exc:  # noqa: BLE001 - a callback must never raise
        stats.bad(key, exc)
        return None


class Inbox:
    """A thread-safe queue of ``Received`` samples, filled by zenoh callbacks.

    ``waker``, when given, is notified after every arrival: a consumer that waits for several
    inboxes at once (the lockstep handshake) blocks on it instead of polling.
    """

    def __init__(self, maxsize: int = 0, waker: threading.Condition | None = None) -> None:
        self._q: queue.Queue[Received] = queue.Queue(maxsize)
        self.overflow = 0
        self._waker = waker

    def put(self, item: Received) -> None:
        try:
            self._q.put_nowait(item)
        except queue.Full:
            self.overflow += 1
        if self._waker is not None:
            with self._waker:
                self._waker.notify_all()

    def drain(self) -> list[Received]:
        """Everything queued so far, oldest first; never blocks."""
        out: list[Received] = []
        while True:
            try:
                out.append(self._q.get_nowait())
            except queue.Empty:
                return out

    def qsize(self) -> int:
        """Samples waiting (approximate while producers run)."""
        return self._q.qsize()

    def get(self, timeout: float) -> Received | None:
        """The next sample, waiting at most ``timeout`` seconds."""
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None

    def __iter__(self) -> Iterator[Received]:
        return iter(self.drain())


class Publisher:
    """Publishes messages of one type on one key."""

    def __init__(self, pub: Any, key: str) -> None:
        self._pub = pub
        self.key = key
        self.sent = 0

    def put(self, msg: wire.Message) -> None:
        self._pub.put(wire.encode(msg))
        self.sent += 1

    def matching(self) -> bool:
        """Whether some subscriber on the bus matches this key (the declaration has arrived)."""
        return bool(self._pub.matching_status.matching)


class Bus:
    """A zenoh session for one fleet, with the fleet's key registry. Use as a context manager."""

    def __init__(
        self,
        section: ZenohSection,
        fleet: str,
        *,
        mode: str | None = None,
        listen: Sequence[str] | None = None,
        connect: Sequence[str] | None = None,
        lease_s: float | None = None,
        identity: ZenohIdentity | None = None,
    ) -> None:
        self.fleet = fleet
        self.stats = DecodeStats()
        self._inboxes: list[Inbox] = []
        self._handles: list[Any] = []
        conf = zenoh_config(
            section, mode=mode, listen=listen, connect=connect, lease_s=lease_s, identity=identity
        )
        try:
            self.session = zenoh.open(conf)
        except zenoh.ZError as exc:
            where = list(connect if connect is not None else section.connect)
            here = list(listen if listen is not None else section.listen)
            raise BusError(
                f"cannot open a zenoh {mode or section.mode} session (listen {here}, "
                f"connect {where}): {str(exc).split(' at ')[0]}"
            ) from exc
        self._closed = False

    # -- lifecycle
    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for h in reversed(self._handles):
            try:
                h.undeclare()
            except Exception:  # noqa: BLE001 - best effort on shutdown
                pass
        self._handles.clear()
        self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def drops(self) -> dict[str, int]:
        """What this session dropped: payloads that did not decode, samples a full inbox lost."""
        return {
            "bad_payloads": self.stats.total,
            "inbox_overflow": sum(b.overflow for b in self._inboxes),
        }

    # -- keys
    def key(self, topic: str, **parts: str) -> str:
        return wire.key(topic, self.fleet, **parts)

    # -- publishing
    def publisher(
        self, topic: str, *, command: bool = False, lossless: bool = False, **parts: str
    ) -> Publisher:
        """A publisher on a registered topic. ``command=True``: express delivery, real-time
        priority and drop on congestion (in the lab a late command is worthless), unless
        ``lossless`` (the lockstep dry run, where every command must arrive): then block.
        Otherwise reliable with blocking congestion control."""
        k = self.key(topic, **parts)
        if command:
            pub = self.session.declare_publisher(
                k,
                congestion_control=zenoh.CongestionControl.BLOCK
                if lossless
                else zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.REAL_TIME,
                express=True,
            )
        else:
            pub = self.session.declare_publisher(
                k, congestion_control=zenoh.CongestionControl.BLOCK
            )
        self._handles.append(pub)
        return Publisher(pub, k)

    def put(self, topic: str, msg: wire.Message, **parts: str) -> None:
        """One-off publication (events: plan, estop)."""
        self.session.put(self.key(topic, **parts), wire.encode(msg))

    # -- subscribing
    def subscribe(
        self,
        key_expr: str,
        msg_type: type[wire.Message] | None,
        inbox: Inbox | None = None,
        on_message: Callable[[Received], None] | None = None,
    ) -> Inbox:
        """Decode samples on ``key_expr`` into ``inbox`` (created if not given).

        ``msg_type`` None decodes by the key's registered topic. ``on_message``, if given, runs
        after enqueueing on zenoh's thread: keep it short.
        """
        box = inbox if inbox is not None else Inbox()
        self._inboxes.append(box)
        fleet = self.fleet
        stats = self.stats

        def callback(sample: zenoh.Sample) -> None:
            k = str(sample.key_expr)
            try:
                payload = sample.payload.to_bytes()
            except Exception as exc:  # noqa: BLE001 - a callback must never raise
                stats.bad(k, exc)
                return
            msg = decode_payload(fleet, k, payload, msg_type, stats)
            if msg is None:
                return
            item = Received(time.time(), k, msg)
            box.put(item)
            if on_message is not None:
                try:
                    on_message(item)
                except Exception:  # noqa: BLE001
                    log.exception("message handler failed on %s", k)

        sub = self.session.declare_subscriber(key_expr, callback)
        self._handles.append(sub)
        return box

    def subscribe_topic(
        self,
        topic: str,
        inbox: Inbox | None = None,
        waker: threading.Condition | None = None,
        **parts: str,
    ) -> Inbox:
        """Decode a registered topic (one key with ``parts``, else every instance) into an inbox
        (a new one notifying ``waker`` unless ``inbox`` is given)."""
        t = wire.TOPICS[topic]
        if inbox is None:
            inbox = Inbox(waker=waker)
        k = t.key(self.fleet, **parts) if parts else t.wildcard(self.fleet)
        return self.subscribe(k, t.msg, inbox)

    def subscribe_raw(self, key_expr: str, callback: Callable[[str, bytes, float], None]) -> None:
        """Raw bytes (key, payload, receive time) for the recorder; the callback must not raise."""

        def cb(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.payload.to_bytes(), time.time())
            except Exception:  # noqa: BLE001
                log.exception("raw subscriber failed on %s", sample.key_expr)

        self._handles.append(self.session.declare_subscriber(key_expr, cb))

    # -- liveliness
    def declare_alive(self, role: str, ident: str) -> Any:
        token = self.session.liveliness().declare_token(wire.alive_key(self.fleet, role, ident))
        self._handles.append(token)
        return token

    def watch_alive(self, role: str, callback: Callable[[str, bool], None]) -> None:
        """``callback(ident, alive)`` when a ``role`` token appears or goes (with history)."""
        prefix = wire.alive_key(self.fleet, role, "")

        def cb(sample: zenoh.Sample) -> None:
            ident = str(sample.key_expr)[len(prefix) :]
            try:
                callback(ident, sample.kind == zenoh.SampleKind.PUT)
            except Exception:  # noqa: BLE001
                log.exception("liveliness handler failed for %s", ident)

        sub = self.session.liveliness().declare_subscriber(
            wire.alive_key(self.fleet, role, "*"), cb, history=True
        )
        self._handles.append(sub)

    # -- queries
    def serve(self, topic: str, responder: Callable[[], wire.Message | None], **parts: str) -> None:
        """Answer queries on a topic's key (``parts`` fill its placeholders) with ``responder()``
        (e.g. the fleet status, a holder's latched e-stop); a None answer sends no reply."""
        k = self.key(topic, **parts)

        def cb(query: zenoh.Query) -> None:
            try:
                msg = responder()
                if msg is not None:
                    query.reply(k, wire.encode(msg))
            except Exception:  # noqa: BLE001
                log.exception("queryable %s failed", k)

        self._handles.append(self.session.declare_queryable(k, cb))

    def query(self, topic: str, msg_type: type[wire.Message], timeout: float) -> list[wire.Message]:
        """Ask every replier on a topic's key; bad replies are counted and dropped."""
        k = self.key(topic)
        return [msg for _, msg in self.query_replies(k, msg_type, timeout)]

    def query_replies(
        self, key_expr: str, msg_type: type[wire.Message], timeout: float
    ) -> Iterator[tuple[str, wire.Message]]:
        """Ask every replier on ``key_expr`` (QueryTarget.ALL): (replier's key, message) as the
        replies come, until all answered or ``timeout``. The caller may stop early (a hung
        replier then costs nothing)."""
        # no consolidation: every replier's answer, also two on one key (an e-stop latch key
        # answered by an impostor as well as by its holder must not hide the holder's answer)
        replies = self.session.get(
            key_expr, target=zenoh.QueryTarget.ALL, consolidation=_EVERY_REPLY, timeout=timeout
        )
        for reply in replies:
            if reply.ok is None:
                continue
            k = str(reply.ok.key_expr)
            try:
                yield k, wire.decode(msg_type, reply.ok.payload.to_bytes())
            except wire.WireError as exc:
                self.stats.bad(k, exc)

    def query_async(
        self, key_expr: str, msg_type: type[wire.Message], inbox: Inbox, timeout: float
    ) -> None:
        """Ask every replier on ``key_expr`` without waiting: decoded replies go into ``inbox``
        (as ``Received`` with the replier's key) on zenoh's thread."""
        stats = self.stats

        def cb(reply: zenoh.Reply) -> None:
            ok = reply.ok
            if ok is None:
                return
            k = str(ok.key_expr)
            try:
                msg = wire.decode(msg_type, ok.payload.to_bytes())
            except Exception as exc:  # noqa: BLE001 - a callback must never raise
                stats.bad(k, exc)
                return
            inbox.put(Received(time.time(), k, msg))

        self.session.get(
            key_expr, cb, target=zenoh.QueryTarget.ALL, consolidation=_EVERY_REPLY, timeout=timeout
        )

    # -- the latched e-stop
    def serve_estop(self, role: str, ident: str, responder: Callable[[], wire.EStop]) -> str:
        """Answer e-stop latch queries as holder ``role``/``ident``; returns the holder's key."""
        self.serve("estop_state", responder, role=role, id=ident)
        return self.key("estop_state", role=role, id=ident)

    def estop_wildcard(self) -> str:
        """The key expression of every holder's latched e-stop."""
        return wire.TOPICS["estop_state"].wildcard(self.fleet)

    def alive_ids_async(self, role: str, sink: list[str], timeout: float = 1.0) -> None:
        """Ask for the ``role`` liveliness tokens without waiting: each ident is appended to
        ``sink`` as its reply comes (on zenoh's thread; read it as ``sink[:]``, an atomic
        copy). A hung peer that never finalises the query then delays nobody."""
        prefix = wire.alive_key(self.fleet, role, "")

        def cb(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                sink.append(str(reply.ok.key_expr)[len(prefix) :])

        self.session.liveliness().get(wire.alive_key(self.fleet, role, "*"), cb, timeout=timeout)

    def alive_ids(self, role: str, timeout: float = 1.0) -> list[str]:
        """The idents of the ``role`` liveliness tokens on the bus now."""
        prefix = wire.alive_key(self.fleet, role, "")
        out = []
        for reply in self.session.liveliness().get(
            wire.alive_key(self.fleet, role, "*"), timeout=timeout
        ):
            if reply.ok is not None:
                out.append(str(reply.ok.key_expr)[len(prefix) :])
        return sorted(set(out))
