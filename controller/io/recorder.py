"""MCAP recording and reading of the bus: one file per run, one channel per key.

The writer is not thread-safe (NOTES.md), so zenoh callbacks only enqueue raw samples and one
writer thread owns the ``mcap.writer.Writer``. Message encoding ``json``; each channel's schema is
its message type's JSON Schema from ``controller.wire``; log time = receive time, publish time =
the message's ``t``. Chunks are zstd-compressed and flushed at least every ``flush_interval`` s,
so a recorder killed without warning leaves a file that still yields every message older than
about one flush interval (``read_log`` reads such a file up to the cut).

Write errors (a full disk, a file-size limit, a folder gone or unwritable) never end the writer
thread: each is counted (``log_errors``), said at most once a second, and the messages that could
not be written are counted (``log_dropped``); the broken segment is left as it is (readable up to
the failure: ``read_log``, ``fleet log recover``) and every ``RETRY_S`` a new segment is tried
(``<stem>-resumed-NNN.mcap`` beside a single file, the next ``_NNN`` of a folder of segments).
While none can be written, events (keys of rate 0: e-stops, phases, plans, robots' failures) are
held in memory, up to ``HELD_MAX``, and written first into the new segment. The queue between the
callbacks and the writer is bounded (``QUEUE_MAX``): when full, the oldest *non-event* sample is
dropped (counted in ``log_dropped``); events and metadata are never dropped.

Native channels (:meth:`McapRecorder.native_channel`) keep other middlewares' messages as they
are: a ROS 2 robot's topics go in with schema encoding ``ros2msg`` and message encoding ``cdr``
under their ROS topic names, so ROS tools (ros2 bag, Foxglove, mcap-ros2-support) read them.
"""

from __future__ import annotations

import collections
import heapq
import json
import logging
import struct
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, BinaryIO, Protocol

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError as zstd_error

from controller import wire

log = logging.getLogger(__name__)

PROFILE = "fleet"
_META = object()  # queue tag of a metadata record
_NATIVE = object()  # queue tag of a native (non-fleet) sample, e.g. a ROS 2 robot's CDR
MAX_PAYLOAD_BYTES = 4 * 1024 * 1024  # a bigger sample is dropped unread (as the bus does)
SIM_EPOCH = 946_684_800.0  # 2000-01-01T00:00:00Z: a dry run's t = 0 (log and publish times)
CLOCK_SKEW = 60.0  # s: a stamp further than this from the run's clock is from another clock
# samples waiting for the writer thread: ≈ 10-20 s of a 50-robot lab (poses, commands, states)
QUEUE_MAX = 100_000
HELD_MAX = 10_000  # events held while no segment can be written
BATCH_S = 0.05  # s: the writer takes what is queued at least this often (unless kicked)
RETRY_S = 1.0  # s between attempts at a new segment after a write error; also the log's pace


class _Queue:
    """The recorder's queue: FIFO, bounded to ``maxsize`` droppable items (the oldest dropped
    first when full); items put with ``keep`` (events, metadata, the end) are never dropped.

    The writer takes everything queued at once (``take``), woken by ``kick`` (the lab daemon's,
    once per tick), by an item put with ``keep``, or after its timeout, never by each sample: a
    wake-up per sample handed the GIL to the writer thread after every ``put`` of the daemon's
    tick (the daemon's own puts reach the recorder at once, through zenoh's local delivery)."""

    def __init__(self, maxsize: int) -> None:
        self.maxsize = maxsize
        self._keep: collections.deque[tuple[int, Any]] = collections.deque()
        self._drop: collections.deque[tuple[int, Any]] = collections.deque()
        self._n = 0
        self._cv = threading.Condition()
        self._kicked = False
        self.dropped = 0

    def put(self, item: Any, keep: bool = False) -> None:
        with self._cv:
            self._n += 1
            if keep:
                self._keep.append((self._n, item))
                self._kicked = True
                self._cv.notify()
            else:
                if len(self._drop) >= self.maxsize:
                    self._drop.popleft()
                    self.dropped += 1
                self._drop.append((self._n, item))

    def kick(self) -> None:
        """Wake the writer now (it takes what is queued)."""
        with self._cv:
            self._kicked = True
            self._cv.notify()

    def take(self, timeout: float) -> list[Any]:
        """Every item queued, oldest first, once kicked or after ``timeout`` s (maybe none)."""
        with self._cv:
            self._cv.wait_for(lambda: self._kicked, timeout=timeout)
            self._kicked = False
            keep, drop = self._keep, self._drop
            self._keep, self._drop = collections.deque(), collections.deque()
        return [item for _, item in heapq.merge(keep, drop, key=lambda e: e[0])]

    def qsize(self) -> int:
        with self._cv:
            return len(self._keep) + len(self._drop)


@dataclass(frozen=True)
class LogRecord:
    """One recorded message: key (topic), times in ns, the raw JSON payload and its schema name."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    schema: str

    def decoded(self) -> dict[str, Any]:
        return json.loads(self.data)

    def message(self) -> wire.Message | None:
        """The payload as its wire type (None if the schema is not one of ours)."""
        cls = wire.MESSAGE_TYPES.get(self.schema)
        return None if cls is None else wire.decode(cls, self.data)


class Tap(Protocol):
    """Something fed every message the recorder writes (the live view): ``offer`` must never
    block (the recorder's thread calls it); ``close`` after the last one."""

    def offer(
        self, topic: str, schema: str, schema_data: bytes, payload: bytes, log_time_ns: int
    ) -> None: ...

    def close(self) -> None: ...

    def drops(self) -> dict[str, int]: ...


class McapRecorder:
    """Writes samples to an MCAP file from a dedicated thread.

    ``on_sample(key, payload, recv_time)`` may be called from any thread (zenoh callbacks).

    Times: in the lab (``sim_epoch`` None) log time is the receive time (wall clock) and publish
    time the message's ``t`` (the sender's wall clock). In a dry run (``sim_epoch`` given) both
    are the message's ``t`` (sim seconds) on that epoch, so a player's timeline is sim time.

    ``scene`` (a ``controller.scene.builder.SceneBuilder``) adds the Foxglove scene channels;
    ``taps`` get every message written (the live view). ``split_s`` > 0 writes a folder of
    segments (``<path without suffix>/<stem>_000.mcap``, ...), each closed and indexed once it
    spans ``split_s`` seconds of log time, each starting with the metadata records: a crash loses
    only the open segment's index (``fleet log recover`` rebuilds it).
    """

    def __init__(
        self,
        path: str | Path,
        fleet: str,
        flush_interval: float = 0.5,
        *,
        sim_epoch: float | None = None,
        split_s: float = 0.0,
        scene: Any = None,
        taps: Sequence[Tap] = (),
    ) -> None:
        self.path = Path(path)
        self.fleet = fleet
        self.flush_interval = flush_interval
        self.sim_epoch = sim_epoch
        self.split_s = split_s
        self.scene = scene
        self.taps = list(taps)
        self.location = self.path.with_suffix("") if split_s > 0 else self.path
        self.segments: list[Path] = []
        self._meta: list[tuple[str, dict[str, str]]] = []
        self._bad_keys: set[str] = set()
        self._logged: dict[str, bool] = {}  # key: whether the registry logs it
        self._events: dict[str, bool] = {}  # key: whether it carries events (never dropped)
        # native channels: key -> (topic, schema name, schema encoding, schema, message encoding)
        self._native: dict[str, tuple[str, str, str, bytes, str]] = {}
        self._segment_start: int | None = None
        self._open_segment()
        self._q = _Queue(QUEUE_MAX)
        self.log_errors = 0  # write errors (each failed write, flush or new segment)
        self.write_dropped = 0  # messages lost to write errors (not in any segment)
        self._broken = False  # the current segment failed: no writer until a new one opens
        self._held: list[tuple[Any, ...]] = []  # events kept while broken
        self._unflushed = 0  # messages added since the last flush (lost if that flush fails)
        self._retry_at = 0.0
        self._said_at = -1e9
        self._sim_t = 0.0  # the latest plausible sim time seen (dry run)
        self._last_log_ns = 0
        self.written = 0  # bus messages
        self.scene_written = 0
        self.native_written = 0  # native channels' messages (ROS 2 robots)
        self.dropped = 0  # samples not written: bad payloads and anything else that failed
        self.bad_payloads = 0  # of those: payloads that do not decode as their key's type
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)
        self._thread.start()
        self._closed = False
        if sim_epoch is not None:
            self.metadata("fleet.time", {"base": "sim", "epoch_s": repr(float(sim_epoch))})

    def _open_segment(self) -> None:
        if self.split_s > 0:
            self.location.mkdir(parents=True, exist_ok=True)
            seg = self.location / f"{self.location.name}_{len(self.segments):03d}.mcap"
        elif not self.segments:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            seg = self.path
        else:  # after a write error: a continuation beside the file
            seg = self.path.with_name(f"{self.path.stem}-resumed-{len(self.segments):03d}.mcap")
        self._stream: BinaryIO = open(seg, "wb")  # noqa: SIM115 - owned by the thread
        self.segments.append(seg)
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="fleet-controller")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str, bytes]] = {}  # key: (id, schema, its data)
        for name, data in self._meta:
            self._writer.add_metadata(name, data)
        self._writer.flush()
        self._segment_start = None
        if self.scene is not None:
            self.scene.resend()

    def _next_segment(self) -> None:
        self._writer.finish()
        self._stream.close()
        self._unflushed = 0  # all in the finished segment
        self._open_segment()

    def on_sample(self, key: str, payload: bytes, recv_time: float) -> None:
        logged = self._logged.get(key)
        if logged is None:
            topic = wire.topic_for_key(self.fleet, key)
            logged = self._logged[key] = topic is None or topic.logged
        if not logged:
            return  # the registry says so (status replies, liveliness)
        self._q.put((key, payload, recv_time), keep=self._is_event(key))

    def _is_event(self, key: str) -> bool:
        """Whether ``key`` carries events (rate 0 in the registry: e-stops, phases, plans,
        robots' failures), which are never dropped."""
        event = self._events.get(key)
        if event is None:
            topic = wire.topic_for_key(self.fleet, key)
            event = self._events[key] = topic is not None and topic.rate_hz == 0.0
        return event

    def native_channel(
        self,
        key: str,
        topic: str,
        schema: str,
        schema_text: str,
        schema_encoding: str = "ros2msg",
        message_encoding: str = "cdr",
    ) -> None:
        """Record the samples of ``key`` (fed to :meth:`on_native`) unchanged on ``topic``, e.g.
        a ROS 2 robot's ``cmd_vel`` as ``geometry_msgs/msg/Twist`` in CDR."""
        enc = schema_text.encode()
        self._native[key] = (topic, schema, schema_encoding, enc, message_encoding)

    def on_native(self, key: str, payload: bytes, recv_time: float) -> None:
        """A sample of a native channel (any thread); other keys are ignored."""
        if key in self._native:
            self._q.put((_NATIVE, key, payload, recv_time))

    def record(self, key: str, msg: wire.Message, recv_time: float | None = None) -> None:
        """Record a message that did not come over the bus (e.g. the run summary)."""
        self.on_sample(key, wire.encode(msg), time.time() if recv_time is None else recv_time)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP metadata record (e.g. the run's config), written in order with the messages,
        so a file cut by a crash still carries it (and every later segment starts with it)."""
        self._q.put((_META, name, {str(k): str(v) for k, v in data.items()}), keep=True)

    def _channel(self, key: str) -> tuple[int, str, bytes]:
        """The channel of a bus key: (id, schema name, schema data)."""
        found = self._channels.get(key)
        if found is not None:
            return found
        topic = wire.topic_for_key(self.fleet, key)
        name, data = "", b""
        if topic is not None and topic.msg is not wire.Message:
            name = topic.msg.TYPE
            data = _schema_data(topic.msg)
        ch = self._writer.register_channel(key, "json", self._schema_id(name, data))
        self._channels[key] = (ch, name, data)
        return self._channels[key]

    def _schema_id(self, name: str, data: bytes, encoding: str = "jsonschema") -> int:
        if not name:
            return 0
        tag = name if encoding == "jsonschema" else f"{encoding}:{name}"
        sid = self._schemas.get(tag)
        if sid is None:
            sid = self._writer.register_schema(name, encoding, data)
            self._schemas[tag] = sid
        return sid

    def _native_channel(self, key: str) -> tuple[int, str, bytes]:
        found = self._channels.get(key)
        if found is None:
            topic, name, schema_enc, data, msg_enc = self._native[key]
            ch = self._writer.register_channel(
                topic, msg_enc, self._schema_id(name, data, schema_enc)
            )
            found = self._channels[key] = (ch, name, data)
        return found

    def _write_native(self, key: str, payload: bytes, recv_time: float) -> None:
        """A native sample as it came (not decoded: its own tools read it); stamped on
        receipt (in a dry run: the run's latest sim time)."""
        if len(payload) > MAX_PAYLOAD_BYTES:
            self._bad(key, f"payload of {len(payload)} bytes > {MAX_PAYLOAD_BYTES}")
            return
        log_ns = self._times(recv_time if self.sim_epoch is None else self._sim_t, recv_time)[0]
        for _ in range(2):
            ch, _, _ = self._native_channel(key)
            try:
                self._add(ch, log_ns, log_ns, payload)
                break
            except _Rolled:
                continue
        self.native_written += 1

    def _times(self, t: Any, recv_time: float) -> tuple[int, int]:
        """(log, publish) times in ns of a message stamped ``t`` received at ``recv_time``."""
        t = float(t)
        if self.sim_epoch is None:
            return int(recv_time * 1e9), max(0, int(t * 1e9))
        if abs(t - self._sim_t) > CLOCK_SKEW and self.written:
            t = self._sim_t  # stamped by another clock (an operator's e-stop): now, in sim time
        self._sim_t = max(self._sim_t, t)
        ns = max(0, int(round((self.sim_epoch + t) * 1e9)))
        return ns, ns

    def _add(self, ch: int, log_ns: int, pub_ns: int, data: bytes) -> None:
        if self._segment_start is None:
            self._segment_start = log_ns
        elif self.split_s > 0 and log_ns - self._segment_start >= self.split_s * 1e9:
            self._next_segment()
            self._segment_start = log_ns
            raise _Rolled
        self._writer.add_message(
            ch, log_time=log_ns, publish_time=pub_ns, data=data, sequence=self.written & 0xFFFFFFFF
        )
        self._unflushed += 1

    def _bad(self, key: str, why: Any) -> None:
        """A payload that does not decode: counted and dropped, one quiet line per key (no
        traceback: a bad payload is the sender's fault, not the recorder's)."""
        self.dropped += 1
        self.bad_payloads += 1
        if key not in self._bad_keys:
            self._bad_keys.add(key)
            log.warning("recorder: dropped a bad payload on %s (more are counted): %s", key, why)

    def _decode(self, key: str, payload: bytes) -> Any:
        """The payload as JSON data, validated against its key's registered type (a key
        without one: any JSON object); raises ValueError when it is bad."""
        if len(payload) > MAX_PAYLOAD_BYTES:
            raise ValueError(f"payload of {len(payload)} bytes > {MAX_PAYLOAD_BYTES}")
        topic = wire.topic_for_key(self.fleet, key)
        if topic is not None and topic.msg is not wire.Message:
            return wire.to_dict(wire.decode(topic.msg, payload))
        try:
            return json.loads(payload)
        except RecursionError as exc:
            raise ValueError("nested too deep") from exc

    def _write(self, key: str, payload: bytes, recv_time: float) -> None:
        try:
            obj = self._decode(key, payload)
            t = obj.get("t", recv_time) if isinstance(obj, dict) else recv_time
            log_ns, pub_ns = self._times(t, recv_time)
        except (ValueError, TypeError, OverflowError) as exc:
            self._bad(key, exc)
            return
        self._put(key, None, payload, log_ns, pub_ns)
        self.written += 1
        self._last_log_ns = log_ns
        if self.scene is not None:
            for m in self.scene.ingest(key, obj):
                self._write_scene(m, log_ns)

    def _put(self, key: str, scene_schema: str | None, data: bytes, log_ns: int, pub_ns: int):
        """Add one message on its channel (the channel is looked up again after a new segment
        began) and hand it to the taps."""
        for _ in range(2):
            if scene_schema is None:
                ch, name, sdata = self._channel(key)
            else:
                ch, name, sdata = self._scene_channel(key, scene_schema)
            try:
                self._add(ch, log_ns, pub_ns, data)
                break
            except _Rolled:
                continue
        for tap in self.taps:
            tap.offer(key, name, sdata, data, log_ns)

    def _scene_channel(self, topic: str, name: str) -> tuple[int, str, bytes]:
        from controller.scene.builder import schema_bytes

        found = self._channels.get(topic)
        if found is not None:
            return found
        data = schema_bytes(name)
        ch = self._writer.register_channel(topic, "json", self._schema_id(name, data))
        self._channels[topic] = (ch, name, data)
        return self._channels[topic]

    def _write_scene(self, m: Any, log_ns: int) -> None:
        """A scene message: stamped with the run's clock (its header times too); in the lab
        logged at the receive time of the bus message that completed it, like that message."""
        stamp = max(0, int(round(m.stamp * 1e9)))
        self._put(
            m.topic, m.schema, m.payload(), stamp if self.sim_epoch is not None else log_ns, stamp
        )
        self.scene_written += 1

    def _run(self) -> None:
        last_flush = time.monotonic()
        end = False
        while not end:
            since = time.monotonic() - last_flush
            for item in self._q.take(max(0.0, min(BATCH_S, self.flush_interval - since))):
                if item is None:
                    end = True
                    break
                if self._broken and time.monotonic() >= self._retry_at:
                    self._reopen()
                if self._broken:
                    self._hold(item)
                else:
                    try:
                        self._handle(item)
                    except OSError as exc:
                        self._failed(exc, lost=1)
            if self._broken and time.monotonic() >= self._retry_at:
                self._reopen()  # nothing queued meanwhile: still a new segment, on time
            if time.monotonic() - last_flush >= self.flush_interval:
                self._flush()
                last_flush = time.monotonic()
        self._finish()

    def kick(self) -> None:
        """Have the writer take what is queued now (the lab daemon: once per tick, after the
        tick's puts, so the writer works while the loop sleeps); else it wakes every
        ``BATCH_S``."""
        self._q.kick()

    def _flush(self) -> None:
        if self._broken:
            return
        try:
            self._writer.flush()
        except OSError as exc:
            self._failed(exc)
            return
        self._unflushed = 0

    def _failed(self, exc: OSError, lost: int = 0) -> None:
        """A write failed: count it and what it lost, say so (at most once per ``RETRY_S``),
        leave the segment as it is and try a new one in ``RETRY_S``."""
        self.log_errors += 1
        self.write_dropped += lost + (self._unflushed if not self._broken else 0)
        self._unflushed = 0
        if not self._broken:
            try:
                self._stream.close()
            except OSError:
                pass  # its buffer cannot be written either
        self._broken = True
        self._retry_at = time.monotonic() + RETRY_S
        self._say(f"cannot write {self.segments[-1]}: {exc}")

    def _say(self, what: str) -> None:
        now = time.monotonic()
        if now - self._said_at >= RETRY_S:
            self._said_at = now
            log.error(
                "recorder: %s (%d write errors, %d messages not logged so far); the fleet goes "
                "on, a new segment is tried every %g s",
                what,
                self.log_errors,
                self.write_dropped + self._q.dropped,
                RETRY_S,
            )

    def _hold(self, item: tuple[Any, ...]) -> None:
        """An item while no segment can be written: metadata kept, events held, the rest lost."""
        if not item:
            return
        if item[0] is _META:
            self._meta.append((item[1], item[2]))
        elif item[0] is not _NATIVE and self._is_event(item[0]) and len(self._held) < HELD_MAX:
            self._held.append(item)
        else:
            self.write_dropped += 1

    def _reopen(self) -> None:
        """A new segment after a write error (its metadata first, then the events held)."""
        self._retry_at = time.monotonic() + RETRY_S
        try:
            self._open_segment()
        except OSError as exc:
            self.log_errors += 1
            self._say(f"cannot open a new segment: {exc}")
            return
        self._broken = False
        self._unflushed = 0
        log.warning(
            "recorder: writing again, to %s (%d write errors, %d messages not logged)",
            self.segments[-1],
            self.log_errors,
            self.write_dropped + self._q.dropped,
        )
        held, self._held = self._held, []
        for item in held:
            try:
                self._handle(item)
            except OSError as exc:
                self._failed(exc, lost=1)
                return

    def _handle(self, item: tuple[Any, ...]) -> None:
        if item and item[0] is _META:
            self._meta.append((item[1], item[2]))
            self._writer.add_metadata(item[1], item[2])
        elif item and item[0] is _NATIVE:
            try:
                self._write_native(*item[1:])
            except Exception:  # noqa: BLE001 - never lose the thread
                self.dropped += 1
                log.exception("could not record a native sample on %s", item[1])
        elif item:
            try:
                self._write(*item)
            except OSError:
                raise  # a write error: _run counts it and goes on
            except Exception:  # noqa: BLE001 - never lose the thread
                self.dropped += 1
                log.exception("could not record a sample on %s", item[0])

    def _finish(self) -> None:
        if self._broken:
            self._reopen()  # one last try: the events held, the index
        if self._broken:
            self.write_dropped += len(self._held)
            return
        try:
            if self.scene is not None:
                try:
                    for m in self.scene.flush():
                        self._write_scene(m, self._last_log_ns)
                except OSError:
                    raise
                except Exception:  # noqa: BLE001 - the log matters more than its last frame
                    log.exception("could not write the last scene frame")
            self._writer.finish()
            self._stream.close()
        except OSError as exc:
            self._failed(exc)

    def drops(self) -> dict[str, int]:
        """Samples the recorder could not write (e.g. a payload that is not JSON), and what its
        taps dropped (the live view's full queue); ``log_errors`` (write errors: full disk...)
        and ``log_dropped`` (messages not logged: lost to those errors or dropped from the full
        queue)."""
        out = {
            "recorder_dropped": self.dropped,
            "log_errors": self.log_errors,
            "log_dropped": self.write_dropped + self._q.dropped,
        }
        for tap in self.taps:
            out.update(tap.drops())
        return out

    def close(self) -> None:
        """Write everything queued, finish the file (summary, index) and close it; then the
        taps."""
        if self._closed:
            return
        self._closed = True
        self._q.put(None, keep=True)
        self._thread.join()
        for tap in self.taps:
            tap.close()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Rolled(Exception):
    """A new segment began: register the channel again and add the message there."""


@cache
def _schema_data(cls: type[wire.Message]) -> bytes:
    return json.dumps(wire.json_schema(cls)).encode()


def segments(path: str | Path) -> list[Path]:
    """The MCAP files of a log: the file itself, or a folder's segments in order."""
    path = Path(path)
    if path.is_dir():
        return sorted(path.glob("*.mcap"))
    # a single file continued after a write error (``<stem>-resumed-NNN.mcap``)
    return [path, *sorted(path.parent.glob(f"{path.stem}-resumed-[0-9][0-9][0-9].mcap"))]


def read_log(path: str | Path, topics: list[str] | None = None) -> Iterator[LogRecord]:
    """Every message of an MCAP file (or a folder of segments) in file order; a file cut short
    by a crash is read up to the last complete record (chunks are flushed at least once per
    flush interval)."""
    for seg in segments(path):
        yield from _read_file(seg, topics)


def _read_file(path: Path, topics: list[str] | None) -> Iterator[LogRecord]:
    wanted = set(topics) if topics is not None else None
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, int]] = {}
    with open(path, "rb") as f:
        reader = StreamReader(f)
        try:
            for rec in reader.records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, Channel):
                    channels[rec.id] = (rec.topic, rec.schema_id)
                elif isinstance(rec, Message):
                    topic, schema_id = channels[rec.channel_id]
                    if wanted is not None and topic not in wanted:
                        continue
                    yield LogRecord(
                        topic,
                        rec.log_time,
                        rec.publish_time,
                        bytes(rec.data),
                        schemas.get(schema_id, ""),
                    )
        except (McapError, EOFError, struct.error, zstd_error) as exc:
            log.info("%s ends early (%s): read up to the cut", path, type(exc).__name__)


def config_metadata(cfg: Any, mode: str) -> dict[str, str]:
    """The ``fleet.config`` metadata record of a run: the config as JSON, its file, the mode."""
    from controller.config import config_to_dict

    data = drop_none(config_to_dict(cfg))
    data.pop("source", None)
    return {"source": cfg.source, "mode": mode, "config": json.dumps(data)}


def drop_none(data: Any) -> Any:
    """The data without its None values (a config key left out, like ``object.goal`` of a
    capture-only job: TOML has no null, and the loader reads an absent key as None)."""
    if isinstance(data, dict):
        return {k: drop_none(v) for k, v in data.items() if v is not None}
    if isinstance(data, list):
        return [drop_none(v) for v in data]
    return data


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The metadata records of an MCAP file by name (a crash-cut file: those before the cut; a
    folder of segments: its first segment's)."""
    out: dict[str, dict[str, str]] = {}
    files = segments(path)
    if not files:
        return out
    with open(files[0], "rb") as f:
        try:
            for rec in StreamReader(f).records:
                if isinstance(rec, Metadata):
                    out[rec.name] = dict(rec.metadata)
        except (McapError, EOFError, struct.error, zstd_error) as exc:
            log.info("%s ends early (%s): read up to the cut", path, type(exc).__name__)
    return out


def log_is_complete(path: str | Path) -> bool:
    """Whether the file (every segment of a folder) was finished (footer and closing magic
    present): False after a crash."""
    files = segments(path)
    return bool(files) and all(_file_complete(f) for f in files)


def _file_complete(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(0, 2)
        if f.tell() < 8 + 37:
            return False
        f.seek(-8, 2)
        return f.read(8) == b"\x89MCAP0\r\n"


def default_log_path(log_dir: str, fleet: str, kind: str = "run") -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    return Path(log_dir) / f"{fleet}-{kind}-{stamp}.mcap"
