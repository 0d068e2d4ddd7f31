"""The bus: one zenoh session per process role, built from the ``[zenoh]`` config section.

I/O edge only (the planning core never imports this). Publishers encode with ``controller.wire``;
subscriber callbacks run on zenoh's thread and only check the payload's size (over
``zenoh.max_payload`` it is dropped unread, counted) and stage the raw bytes for the session's
decoder thread, which decodes them into the subscriber's ``Inbox`` (a bad payload is counted and
logged once per burst, never raised). Staging and inboxes keep at most ``zenoh.inbox_depth``
samples per key (a flood drops the oldest, counted), except the lossless ones (lockstep).
Liveliness tokens mark presence; a queryable serves the fleet status.

Zenoh facts this relies on (NOTES.md): a session that is not closed hangs the process at exit,
so ``Bus`` is a context manager and every test closes it; a channel subscriber you keep no
reference to is silently undeclared, so the bus keeps every handle it creates.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from controller import wire
from controller.config import ConfigError, ZenohIdentity, ZenohSection

log = logging.getLogger(__name__)

#: bytes: the codec's own ceiling; a session drops anything over ``zenoh.max_payload`` (64 KiB
#: by default) before this, unread
MAX_PAYLOAD_BYTES = 4 * 1024 * 1024
#: command publishers' zenoh ``express`` flag: off, so a tick's burst of commands shares a batch
#: (``Bus.publisher``; ``bench/command_burst.py`` measures both)
EXPRESS_COMMANDS = False


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
    """Authentication, TLS and access control (docs/lab/secure.md)."""
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
    open_timeout_s: float | None = None,
) -> zenoh.Config:
    """A zenoh Config from the ``[zenoh]`` section, with per-role overrides: every session of
    every role is built here. ``open_timeout_s``: how long a link's handshake may take (zenoh:
    10 s; a tool that must not wait on a hung hub sets less).

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
    if section.reconnect_s > 0:  # a lost endpoint retried soon (a hub restart heals fast)
        cap_ms = max(1, int(section.reconnect_s * 1000))
        retry = {"period_init_ms": min(250, cap_ms), "period_max_ms": cap_ms}
        conf.insert_json5("connect/retry", json.dumps(retry | {"period_increase_factor": 2}))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(section.multicast_scouting))
    conf.insert_json5("scouting/gossip/enabled", json.dumps(section.gossip_scouting))
    if open_timeout_s is not None:
        conf.insert_json5("transport/unicast/open_timeout", json.dumps(int(open_timeout_s * 1000)))
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
            "zenoh.acl: docs/lab/secure.md)",
            ", ".join(exposed),
        )
    return conf


_EVERY_REPLY = zenoh.ConsolidationMode.NONE  # queries: every reply, none merged by key
_MIN_QUERY_S = 0.001


def _positive(timeout: float) -> float:
    """A query's timeout as zenoh takes it: a deadline already passed (a caller's time left,
    gone negative on a loaded machine) still asks once, briefly, and never raises."""
    return max(float(timeout), _MIN_QUERY_S)


@dataclass(frozen=True)
class Received:
    """One decoded sample: receive time (s, ``time.time()``), key and message."""

    recv_time: float
    key: str
    msg: wire.Message


class BusError(ConnectionError):
    """The zenoh session could not be opened (e.g. a client found nothing to connect to)."""


class DecodeStats:
    """Counts payloads that did not decode (oversized ones apart too) and samples a full inbox
    dropped, per key; logs the first of each burst."""

    def __init__(self, quiet_after: float = 5.0) -> None:
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}
        self.oversize: dict[str, int] = {}
        self.overflow: dict[str, int] = {}
        self.rate_limited: dict[str, int] = {}
        self._last_logged: dict[tuple[str, str], float] = {}
        self._quiet_after = quiet_after

    def _count(self, table: dict[str, int], what: str, key: str, detail: object) -> None:
        now = time.monotonic()
        with self._lock:
            n = table[key] = table.get(key, 0) + 1
            last = self._last_logged.get((what, key))
            if last is None or now - last > self._quiet_after:
                self._last_logged[(what, key)] = now
                log.warning("dropped %s on %s (%d so far): %s", what, key, n, detail)

    def bad(self, key: str, err: Exception) -> None:
        """A payload that did not decode."""
        self._count(self.counts, "a bad payload", key, err)

    def too_large(self, key: str, size: int, limit: int) -> None:
        """A payload over the session's limit, dropped unread (also a bad payload)."""
        self._count(self.oversize, "an oversized payload", key, f"{size} bytes > {limit}")
        with self._lock:
            self.counts[key] = self.counts.get(key, 0) + 1

    def overflowed(self, key: str) -> None:
        """A full inbox dropped the oldest sample of ``key``."""
        self._count(self.overflow, "the oldest queued sample (inbox full)", key, "a flood?")

    def overwritten(self, key: str, n: int) -> None:
        """``n`` samples of ``key`` a ring overwrote before they were read (a flood)."""
        if n <= 0:
            return
        self._count(self.overflow, "samples overwritten unread (ring full)", key, "a flood?")
        with self._lock:
            self.overflow[key] += n - 1

    def too_fast(self, key: str, rate_hz: float) -> None:
        """A sample of ``key`` over its rate limit, dropped unread."""
        self._count(self.rate_limited, "a sample over the key's rate", key, f"> {rate_hz:g} Hz")

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self.counts.values())

    @property
    def total_rate_limited(self) -> int:
        with self._lock:
            return sum(self.rate_limited.values())

    @property
    def total_oversize(self) -> int:
        with self._lock:
            return sum(self.oversize.values())


def decode_payload(
    fleet: str,
    key: str,
    payload: bytes,
    msg_type: type[wire.Message] | None,
    stats: DecodeStats,
    max_bytes: int = MAX_PAYLOAD_BYTES,
) -> wire.Message | None:
    """A subscriber's decode step: the message, or None after counting a bad payload (over
    ``max_bytes``, not JSON, wrong fields or types, NaN/inf, out-of-range magnitudes, no
    registered type for ``key``). Never raises."""
    try:
        if len(payload) > max_bytes:
            raise wire.WireError(f"payload of {len(payload)} bytes > {max_bytes}")
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
    """A thread-safe inbox of ``Received`` samples, filled by the bus's decoder thread (or
    anyone: replies, replays, tests), emptied oldest first.

    Bounds (0: none): ``depth`` samples per key, a new one then drops that key's oldest (a
    flooding key evicts only its own samples); ``maxsize`` samples in all, a new one then is
    dropped itself. Both count in ``overflow`` and call ``on_drop(key)``. Lossless paths (the
    lockstep clock and its answers) use neither.

    ``waker``, when given, is notified after every arrival: a consumer that waits for several
    inboxes at once (the lockstep handshake) blocks on it instead of polling.
    """

    def __init__(
        self,
        maxsize: int = 0,
        waker: threading.Condition | None = None,
        depth: int = 0,
        on_drop: Callable[[str], None] | None = None,
    ) -> None:
        self._cond = threading.Condition()
        self._buckets: dict[Any, deque[tuple[int, Any]]] = {}
        self._n = 0
        self._seq = 0
        self.maxsize = maxsize
        self.depth = depth
        self.overflow = 0
        self._on_drop = on_drop
        self._waker = waker

    def _add(self, bucket: Any, key: str, entry: Any) -> None:
        dropped = False
        with self._cond:
            if self.maxsize and self._n >= self.maxsize:
                self.overflow += 1
                dropped = True
            else:
                q = self._buckets.get(bucket)
                if q is None:
                    q = self._buckets[bucket] = deque()
                if self.depth and len(q) >= self.depth:
                    q.popleft()
                    self.overflow += 1
                    dropped = True
                else:
                    self._n += 1
                self._seq += 1
                q.append((self._seq, entry))
                self._cond.notify_all()
        if dropped and self._on_drop is not None:
            self._on_drop(key)
        if self._waker is not None:
            with self._waker:
                self._waker.notify_all()

    def put(self, item: Received) -> None:
        self._add(item.key, item.key, item)

    def _take_all(self) -> list[Any]:
        """Every entry, oldest first (under the lock's protection of the swap)."""
        with self._cond:
            if not self._n:
                return []
            buckets = list(self._buckets.values())
            self._buckets = {}
            self._n = 0
        if len(buckets) == 1:
            return [e for _, e in buckets[0]]
        return [e for _, e in sorted((x for q in buckets for x in q), key=lambda x: x[0])]

    def drain(self) -> list[Received]:
        """Everything queued so far, oldest first; never blocks."""
        return self._take_all()

    def qsize(self) -> int:
        """Samples waiting (approximate while producers run)."""
        return self._n

    def wait(self, timeout: float) -> bool:
        """Whether something is queued, waiting at most ``timeout`` seconds for it."""
        with self._cond:
            return self._cond.wait_for(lambda: self._n > 0, timeout)

    def wake(self) -> None:
        """Wake whoever waits (shutting down)."""
        with self._cond:
            self._cond.notify_all()

    def get(self, timeout: float) -> Received | None:
        """The next sample, waiting at most ``timeout`` seconds."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._n > 0, timeout):
                return None
            bucket = min(self._buckets, key=lambda b: self._buckets[b][0][0])
            q = self._buckets[bucket]
            entry = q.popleft()[1]
            if not q:
                del self._buckets[bucket]
            self._n -= 1
            return entry

    def __iter__(self) -> Iterator[Received]:
        return iter(self.drain())


class RingInbox:
    """Samples of a few keys, each key a zenoh ring of ``capacity`` (the newest kept): zenoh's
    threads write into the rings without Python, so a key flooded at tens of kHz costs the loop
    nothing but the ``capacity`` newest samples it reads at each ``drain`` (issue 31 5c: one
    Python callback per sample, rate-limited or not, cost a flooded daemon 10-15 late ticks
    of 100). Read by the consumer's own thread (the tick), decoded there. What a ring
    overwrote is counted (``overflow``) from the gaps in the messages' ``seq``, only when the
    ring was found full (nothing is overwritten otherwise): exact for one sender counting up,
    an estimate for a sender that jumps. ``on_raw(key, payload, recv_time)`` sees every sample
    read (the daemon's recorder)."""

    #: a gap in a key's ``seq`` counted at most this much per drain (a forged jump)
    MAX_GAP = 1_000_000

    def __init__(
        self,
        bus: Bus,
        keys: Sequence[str],
        msg_type: type[wire.Message],
        capacity: int,
        on_raw: Callable[[str, bytes, float], None] | None = None,
    ) -> None:
        self._bus = bus
        self._type = msg_type
        self.on_raw = on_raw
        self.capacity = capacity
        self.overflow = 0
        self._seq: dict[str, int] = {}
        self._subs = [
            (k, bus.session.declare_subscriber(k, zenoh.handlers.RingChannel(capacity)))
            for k in keys
        ]

    def _count(self, key: str, seqs: list[int]) -> None:
        """The samples a full ring overwrote: the gaps before and between ``seqs`` read."""
        last = self._seq.get(key)
        if seqs:
            self._seq[key] = seqs[-1]
        if last is None:
            return
        gaps = sum(max(0, b - a - 1) for a, b in zip([last, *seqs[:-1]], seqs, strict=True))
        n = min(gaps, self.MAX_GAP)
        if n:
            self.overflow += n
            self._bus.stats.overwritten(key, n)

    def drain(self) -> list[Received]:
        """Every sample the rings hold, key by key, oldest first within a key; never blocks."""
        bus, out = self._bus, []
        now = time.time()
        for key, sub in self._subs:
            read: list[int] = []
            while (sample := sub.try_recv()) is not None:
                read.append(-1)  # a sample read, whatever it holds (the ring's fill)
                payload = bus._payload(sample, key)
                if payload is None:
                    continue
                if self.on_raw is not None:
                    try:
                        self.on_raw(key, payload, now)
                    except Exception:  # noqa: BLE001 - the recorder never stops the loop
                        log.exception("raw reader failed on %s", key)
                msg = decode_payload(bus.fleet, key, payload, self._type, bus.stats,
                                     bus.max_payload)  # fmt: skip
                if msg is None:
                    continue
                read[-1] = int(msg.seq)
                out.append(Received(now, key, msg))
            if len(read) >= self.capacity:
                self._count(key, [q for q in read if q >= 0])
            elif read and read[-1] >= 0:
                self._seq[key] = read[-1]
        return out

    def undeclare(self) -> None:
        for _, sub in self._subs:
            sub.undeclare()


@dataclass(frozen=True)
class _Raw:
    """A sample as it arrived, for the decoder thread: decoded into ``box``."""

    recv_time: float
    key: str
    payload: bytes
    decode: Callable[[str, bytes], wire.Message | None]
    box: Inbox
    on_message: Callable[[Received], None] | None


class KeyRate:
    """Per-key token buckets: a key may deliver ``rate_hz`` samples a second on average, in
    bursts of up to ``burst_s`` seconds' worth (at least 2); what comes faster is refused. One
    per subscription, checked on zenoh's thread before a byte is copied, so a key flooded at
    tens of kHz costs a dictionary look-up per sample, not a decode (issue 31: a robot flooding
    its own pose key at 47 kHz stopped every robot's watchdog 13-15 times in 10 s). At most
    ``MAX_KEYS`` keys are followed (a flood of fresh keys forgets the oldest)."""

    MAX_KEYS = 4096

    def __init__(self, rate_hz: float, burst_s: float = 0.25) -> None:
        self.rate = float(rate_hz)
        self.burst = max(2.0, self.rate * burst_s)
        self._buckets: dict[str, tuple[float, float]] = {}

    def allow(self, key: str, now: float) -> bool:
        """Whether a sample of ``key`` arriving at ``now`` (monotonic s) is within its rate."""
        got = self._buckets.get(key)
        if got is None:
            if len(self._buckets) >= self.MAX_KEYS:
                self._buckets.pop(next(iter(self._buckets)))
            tokens = self.burst
        else:
            tokens = min(self.burst, got[0] + (now - got[1]) * self.rate)
        if tokens < 1.0:
            self._buckets[key] = (tokens, now)
            return False
        self._buckets[key] = (tokens - 1.0, now)
        return True


class Decoder:
    """The bus's decoder thread: zenoh's callbacks only stage the raw bytes (bounded per
    subscriber and key, dropping the oldest); this thread decodes them, in arrival order, into
    the subscribers' inboxes and runs their ``on_message`` handlers. A bad payload is counted
    (by its decode function) and never reaches an inbox."""

    def __init__(self, depth: int, on_drop: Callable[[str], None]) -> None:
        self.stage = Inbox(depth=depth, on_drop=on_drop)
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="bus-decoder", daemon=True)
        self._thread.start()

    def submit(self, raw: _Raw, lossless: bool) -> None:
        """Stage a sample (zenoh's thread); ``lossless`` samples are never evicted."""
        # a lossless sample is a bucket of its own (never full): it waits for its turn
        bucket = (id(raw.box), raw.key) if not lossless else (id(raw.box), raw.key, id(raw))
        self.stage._add(bucket, raw.key, raw)

    def _run(self) -> None:
        while True:
            self.stage.wait(0.5)
            entries = self.stage._take_all()
            if not entries and self._closed:
                return
            for raw in entries:
                self._deliver(raw)

    @staticmethod
    def _deliver(raw: _Raw) -> None:
        msg = raw.decode(raw.key, raw.payload)
        if msg is None:
            return
        item = Received(raw.recv_time, raw.key, msg)
        raw.box.put(item)
        if raw.on_message is not None:
            try:
                raw.on_message(item)
            except Exception:  # noqa: BLE001
                log.exception("message handler failed on %s", raw.key)

    def close(self) -> None:
        self._closed = True
        self.stage.wake()
        self._thread.join(timeout=2.0)


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
        open_timeout_s: float | None = None,
    ) -> None:
        self.fleet = fleet
        self.stats = DecodeStats()
        self.max_payload = section.max_payload  # bytes: larger samples are dropped unread
        self.inbox_depth = section.inbox_depth  # samples per key in a bounded inbox
        self.key_rate_hz = section.key_rate_hz  # samples/s per key into a bounded inbox (0: any)
        self._inboxes: list[Inbox | RingInbox] = []
        self._decoder_thread: Decoder | None = None
        self._handles: list[Any] = []
        conf = zenoh_config(
            section,
            mode=mode,
            listen=listen,
            connect=connect,
            lease_s=lease_s,
            identity=identity,
            open_timeout_s=open_timeout_s,
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
        if self._decoder_thread is not None:
            self._decoder_thread.close()

    def routers(self) -> list[str]:
        """The zids of the routers this session is linked to now (a router: its peers)."""
        return [str(z) for z in self.session.info.routers_zid()]

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def drops(self) -> dict[str, int]:
        """What this session dropped: payloads that did not decode (``bad_payloads``, the
        oversized ones included and also counted apart, ``oversize_payloads``) and samples a
        full inbox or the decoder's staging lost (``inbox_overflow``)."""
        return {
            "bad_payloads": self.stats.total,
            "oversize_payloads": self.stats.total_oversize,
            "inbox_overflow": sum(b.overflow for b in self._inboxes)
            + (self._decoder_thread.stage.overflow if self._decoder_thread else 0),
            "rate_limited": self.stats.total_rate_limited,
        }

    def drops_by_key(self) -> dict[str, dict[str, int]]:
        """The same drops per key: ``{"bad": {key: n}, "oversize": ..., "overflow": ...}``."""
        st = self.stats
        with st._lock:
            return {
                "bad": dict(st.counts),
                "oversize": dict(st.oversize),
                "overflow": dict(st.overflow),
                "rate_limited": dict(st.rate_limited),
            }

    def inbox(self, *, lossless: bool = False, waker: threading.Condition | None = None) -> Inbox:
        """A new inbox bounded at ``zenoh.inbox_depth`` samples per key (dropping the oldest,
        counted), or unbounded when ``lossless``."""
        depth = 0 if lossless else self.inbox_depth
        return Inbox(waker=waker, depth=depth, on_drop=self.stats.overflowed)

    def _decoder(self) -> Decoder:
        """The session's decoder thread, started with the first subscription."""
        if self._decoder_thread is None:
            self._decoder_thread = Decoder(self.inbox_depth, self.stats.overflowed)
        return self._decoder_thread

    def _payload(self, sample: zenoh.Sample, key: str, count: bool = True) -> bytes | None:
        """A sample's bytes, or None after counting it (over ``max_payload``, unreadable):
        the size is checked before anything is copied. ``count`` False: an oversized sample
        is dropped uncounted (the raw tap: a decoding subscriber counts the same sample)."""
        try:
            size = len(sample.payload)
            if size > self.max_payload:
                if count:
                    self.stats.too_large(key, size, self.max_payload)
                return None
            return sample.payload.to_bytes()
        except Exception as exc:  # noqa: BLE001 - a callback must never raise
            self.stats.bad(key, exc)
            return None

    # -- keys
    def key(self, topic: str, **parts: str) -> str:
        return wire.key(topic, self.fleet, **parts)

    # -- publishing
    def publisher(
        self, topic: str, *, command: bool = False, lossless: bool = False, **parts: str
    ) -> Publisher:
        """A publisher on a registered topic. ``command=True``: real-time priority and drop on
        congestion (in the lab a late command is worthless), unless ``lossless`` (the lockstep
        dry run, where every command must arrive): then block. Otherwise reliable with blocking
        congestion control.

        Commands are batched, not express: the daemon puts one per robot in a burst each tick,
        and an express message takes a batch of its own from a queue of two per priority
        (zenoh's ``transport/link/tx/queue/size``), so the third waited 1 ms for the link's
        thread and was dropped on a busy machine: robots 3-6 of 6 lost 2-4 % of their commands
        under load, 48 of 50 robots 8 % (a README lab robot's watchdog fired on 6 lost in a
        row). Batched, a tick's commands share one batch: none lost, p50 +0.1 ms at 6 robots
        (``bench/command_burst.py``)."""
        k = self.key(topic, **parts)
        if command:
            pub = self.session.declare_publisher(
                k,
                congestion_control=zenoh.CongestionControl.BLOCK
                if lossless
                else zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.REAL_TIME,
                express=EXPRESS_COMMANDS,
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
        lossless: bool = False,
    ) -> Inbox:
        """Samples on ``key_expr`` into ``inbox`` (created if not given: bounded per key unless
        ``lossless``, see ``inbox``). On zenoh's thread only the size is checked and the raw
        bytes staged; the bus's decoder thread decodes them into the inbox (staging is bounded
        per key like the inbox, unless ``lossless`` or the inbox is unbounded).

        ``msg_type`` None decodes by the key's registered topic. ``on_message``, if given, runs
        on the decoder thread after enqueueing: keep it short.
        """
        box = inbox if inbox is not None else self.inbox(lossless=lossless)
        self._inboxes.append(box)
        fleet = self.fleet
        stats = self.stats
        limit = self.max_payload

        def decode(k: str, payload: bytes) -> wire.Message | None:
            return decode_payload(fleet, k, payload, msg_type, stats, limit)

        decoder = self._decoder()
        staged_lossless = lossless or (box.depth == 0 and box.maxsize == 0)
        # a bounded inbox takes each key at up to zenoh.key_rate_hz; a lossless one (the
        # lockstep dry run, e-stops, commands) takes everything
        limiter = None if staged_lossless or not self.key_rate_hz else KeyRate(self.key_rate_hz)

        def callback(sample: zenoh.Sample) -> None:
            k = str(sample.key_expr)
            if limiter is not None and not limiter.allow(k, time.monotonic()):
                stats.too_fast(k, limiter.rate)
                return
            payload = self._payload(sample, k)
            if payload is not None:
                raw = _Raw(time.time(), k, payload, decode, box, on_message)
                decoder.submit(raw, staged_lossless)

        sub = self.session.declare_subscriber(key_expr, callback)
        self._handles.append(sub)
        return box

    def subscribe_rings(
        self,
        topic: str,
        ids: Sequence[str],
        on_raw: Callable[[str, bytes, float], None] | None = None,
    ) -> RingInbox:
        """A registered topic's keys for ``ids`` (one ``id`` part each; no ids: its one key),
        each a ring of ``zenoh.inbox_depth`` samples read by the consumer (``RingInbox``): for
        the keys a robot may flood (its poses), which must cost the loop nothing."""
        t = wire.TOPICS[topic]
        keys = [t.key(self.fleet, id=i) for i in ids] if ids else [t.key(self.fleet)]
        box = RingInbox(self, keys, t.msg, self.inbox_depth, on_raw)
        self._inboxes.append(box)
        self._handles.append(box)
        return box

    def subscribe_topic(
        self,
        topic: str,
        inbox: Inbox | None = None,
        waker: threading.Condition | None = None,
        lossless: bool = False,
        **parts: str,
    ) -> Inbox:
        """Decode a registered topic (one key with ``parts``, else every instance) into an inbox
        (a new one notifying ``waker`` unless ``inbox`` is given; bounded per key unless
        ``lossless``)."""
        t = wire.TOPICS[topic]
        if inbox is None:
            inbox = self.inbox(lossless=lossless, waker=waker)
        k = t.key(self.fleet, **parts) if parts else t.wildcard(self.fleet)
        return self.subscribe(k, t.msg, inbox)

    def subscribe_raw(
        self, key_expr: str, callback: Callable[[str, bytes, float], None], *, limit: bool = False
    ) -> None:
        """Raw bytes (key, payload, receive time) for the recorder; the callback must not raise.
        A payload over ``max_payload`` is dropped unread, as for every subscriber; ``limit``
        (the lab's recorder): so is a sample over its key's ``zenoh.key_rate_hz``. Neither is
        counted here (a decoding subscriber counts the same sample)."""
        limiter = KeyRate(self.key_rate_hz) if limit and self.key_rate_hz else None

        def cb(sample: zenoh.Sample) -> None:
            k = str(sample.key_expr)
            if limiter is not None and not limiter.allow(k, time.monotonic()):
                return
            payload = self._payload(sample, k, count=False)
            if payload is None:
                return
            try:
                callback(k, payload, time.time())
            except Exception:  # noqa: BLE001
                log.exception("raw subscriber failed on %s", sample.key_expr)

        self._handles.append(self.session.declare_subscriber(key_expr, cb))

    # -- liveliness
    def subscribe_raw_topics(
        self,
        callback: Callable[[str, bytes, float], None],
        *,
        limit: bool = False,
        skip: Sequence[str] = (),
    ) -> None:
        """``subscribe_raw`` on every logged topic of the registry but ``skip`` (the daemon's
        recorder: the pose keys it skips reach it from the loop's rings, a flood unread).
        Keys of the fleet outside the registry are not taken."""
        for t in wire.TOPICS.values():
            if t.logged and t.name not in skip:
                self.subscribe_raw(t.wildcard(self.fleet), callback, limit=limit)

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
            key_expr,
            target=zenoh.QueryTarget.ALL,
            consolidation=_EVERY_REPLY,
            timeout=_positive(timeout),
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
            key_expr,
            cb,
            target=zenoh.QueryTarget.ALL,
            consolidation=_EVERY_REPLY,
            timeout=_positive(timeout),
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

        self.session.liveliness().get(
            wire.alive_key(self.fleet, role, "*"), cb, timeout=_positive(timeout)
        )

    def alive_ids(self, role: str, timeout: float = 1.0) -> list[str]:
        """The idents of the ``role`` liveliness tokens on the bus now."""
        prefix = wire.alive_key(self.fleet, role, "")
        out = []
        for reply in self.session.liveliness().get(
            wire.alive_key(self.fleet, role, "*"), timeout=_positive(timeout)
        ):
            if reply.ok is not None:
                out.append(str(reply.ok.key_expr)[len(prefix) :])
        return sorted(set(out))


class Paths:
    """Several sessions of one fleet used as one for the e-stop (``zenoh.estop_listen``: the
    hub's, and the daemon's second listener's): a put goes out on each, a query asks on each
    and yields every reply; a session that opens late (a hung hub's) joins when it opens
    (``add``). Quacks like the ``Bus`` the e-stop tool uses."""

    def __init__(self, fleet: str, buses: Sequence[Bus] = ()) -> None:
        self.fleet = fleet
        self._buses = list(buses)
        self._lock = threading.Lock()

    def add(self, bus: Bus) -> None:
        with self._lock:
            self._buses.append(bus)

    def buses(self) -> list[Bus]:
        with self._lock:
            return list(self._buses)

    def key(self, topic: str, **parts: str) -> str:
        return wire.key(topic, self.fleet, **parts)

    def estop_wildcard(self) -> str:
        return wire.TOPICS["estop_state"].wildcard(self.fleet)

    def publisher(self, topic: str, **parts: str) -> _Fanout:
        return _Fanout(self, topic, parts)

    def alive_ids_async(self, role: str, sink: list[str], timeout: float = 1.0) -> None:
        for bus in self.buses():
            bus.alive_ids_async(role, sink, timeout)

    def query(self, topic: str, msg_type: type[wire.Message], timeout: float) -> list[wire.Message]:
        """Every path's replies on a topic's key (a replier on two paths answers twice)."""
        return [msg for _, msg in self.query_replies(self.key(topic), msg_type, timeout)]

    def query_replies(
        self, key_expr: str, msg_type: type[wire.Message], timeout: float
    ) -> Iterator[tuple[str, wire.Message]]:
        """Every path's replies as they come, until every path's query is answered by all or
        ``timeout`` (the caller may stop early; a hung path then costs nothing more)."""
        import queue

        buses = self.buses()
        out: queue.Queue = queue.Queue()

        def ask(bus: Bus) -> None:
            try:
                for reply in bus.query_replies(key_expr, msg_type, timeout):
                    out.put(reply)
            except Exception as exc:  # noqa: BLE001 - a closing session: that path is done
                log.debug("a path's query ended: %s", exc)
            out.put(None)  # this path is done

        for bus in buses:
            threading.Thread(target=ask, args=(bus,), daemon=True).start()
        deadline = time.monotonic() + max(float(timeout), _MIN_QUERY_S)
        pending = len(buses)
        while pending and (left := deadline - time.monotonic()) > 0:
            try:
                item = out.get(timeout=left)
            except queue.Empty:
                return
            if item is None:
                pending -= 1
            else:
                yield item


class _Fanout:
    """One topic's publisher on every path of a ``Paths``, a late path's declared at its first
    put."""

    def __init__(self, paths: Paths, topic: str, parts: dict[str, str]) -> None:
        self._paths, self._topic, self._parts = paths, topic, parts
        self._pubs: dict[int, Publisher] = {}

    def _each(self) -> list[Publisher]:
        for bus in self._paths.buses():
            if id(bus) not in self._pubs:
                self._pubs[id(bus)] = bus.publisher(self._topic, **self._parts)
        return list(self._pubs.values())

    def put(self, msg: wire.Message) -> None:
        for pub in self._each():
            pub.put(msg)

    def matching(self) -> bool:
        return any(pub.matching() for pub in self._each())
