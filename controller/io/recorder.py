"""MCAP recording and reading of the bus: one file per run, one channel per key.

The writer is not thread-safe (NOTES.md), so zenoh callbacks only enqueue raw samples and one
writer thread owns the ``mcap.writer.Writer``. Message encoding ``json``; each channel's schema is
its message type's JSON Schema from ``controller.wire``; log time = receive time, publish time =
the message's ``t``. Chunks are zstd-compressed and flushed at least every ``flush_interval`` s,
so a recorder killed without warning leaves a file that still yields every message older than
about one flush interval (``read_log`` reads such a file up to the cut).
"""

from __future__ import annotations

import json
import logging
import queue
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError as zstd_error

from controller import wire

log = logging.getLogger(__name__)

PROFILE = "fleet"
_META = object()  # queue tag of a metadata record


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


class McapRecorder:
    """Writes samples to an MCAP file from a dedicated thread.

    ``on_sample(key, payload, recv_time)`` may be called from any thread (zenoh callbacks).
    """

    def __init__(self, path: str | Path, fleet: str, flush_interval: float = 0.5) -> None:
        self.path = Path(path)
        self.fleet = fleet
        self.flush_interval = flush_interval
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - owned by the thread
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="fleet-controller")
        self._writer.flush()
        self._q: queue.Queue[tuple[Any, ...] | None] = queue.Queue()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.written = 0
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)
        self._thread.start()
        self._closed = False

    def on_sample(self, key: str, payload: bytes, recv_time: float) -> None:
        topic = wire.topic_for_key(self.fleet, key)
        if topic is not None and not topic.logged:
            return  # the registry says so (status replies, liveliness)
        self._q.put((key, payload, recv_time))

    def record(self, key: str, msg: wire.Message, recv_time: float | None = None) -> None:
        """Record a message that did not come over the bus (e.g. the run summary)."""
        self.on_sample(key, wire.encode(msg), time.time() if recv_time is None else recv_time)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP metadata record (e.g. the run's config), written in order with the messages,
        so a file cut by a crash still carries it."""
        self._q.put((_META, name, {str(k): str(v) for k, v in data.items()}))

    def _channel(self, key: str) -> int:
        ch = self._channels.get(key)
        if ch is not None:
            return ch
        topic = wire.topic_for_key(self.fleet, key)
        schema_id = 0
        if topic is not None and topic.msg is not wire.Message:
            name = topic.msg.TYPE
            schema_id = self._schemas.get(name, 0)
            if not schema_id:
                data = json.dumps(wire.json_schema(topic.msg)).encode()
                schema_id = self._writer.register_schema(name, "jsonschema", data)
                self._schemas[name] = schema_id
        ch = self._writer.register_channel(key, "json", schema_id)
        self._channels[key] = ch
        return ch

    def _write(self, key: str, payload: bytes, recv_time: float) -> None:
        try:
            obj = json.loads(payload)
            t = obj.get("t", recv_time) if isinstance(obj, dict) else recv_time
            pub_ns = int(float(t) * 1e9)
        except (ValueError, TypeError, OverflowError):
            self.dropped += 1
            return
        self._writer.add_message(
            self._channel(key),
            log_time=int(recv_time * 1e9),
            publish_time=max(0, pub_ns),
            data=payload,
            sequence=self.written & 0xFFFFFFFF,
        )
        self.written += 1

    def _run(self) -> None:
        last_flush = time.monotonic()
        while True:
            timeout = max(0.0, self.flush_interval - (time.monotonic() - last_flush))
            try:
                item = self._q.get(timeout=timeout)
            except queue.Empty:
                item = ()  # type: ignore[assignment]
            if item is None:
                break
            if item and item[0] is _META:
                self._writer.add_metadata(item[1], item[2])
            elif item:
                try:
                    self._write(*item)
                except Exception:  # noqa: BLE001 - never lose the thread
                    self.dropped += 1
                    log.exception("could not record a sample on %s", item[0])
            if time.monotonic() - last_flush >= self.flush_interval:
                self._writer.flush()
                last_flush = time.monotonic()
        self._writer.finish()
        self._stream.close()

    def drops(self) -> dict[str, int]:
        """Samples the recorder could not write (e.g. a payload that is not JSON)."""
        return {"recorder_dropped": self.dropped}

    def close(self) -> None:
        """Write everything queued, finish the file (summary, index) and close it."""
        if self._closed:
            return
        self._closed = True
        self._q.put(None)
        self._thread.join()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_log(path: str | Path, topics: list[str] | None = None) -> Iterator[LogRecord]:
    """Every message of an MCAP file in file order; a file cut short by a crash is read up to
    the last complete record (chunks are flushed at least once per flush interval)."""
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

    data = config_to_dict(cfg)
    data.pop("source", None)
    return {"source": cfg.source, "mode": mode, "config": json.dumps(data)}


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The metadata records of an MCAP file by name (a crash-cut file: those before the cut)."""
    out: dict[str, dict[str, str]] = {}
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f).records:
                if isinstance(rec, Metadata):
                    out[rec.name] = dict(rec.metadata)
        except (McapError, EOFError, struct.error, zstd_error) as exc:
            log.info("%s ends early (%s): read up to the cut", path, type(exc).__name__)
    return out


def log_is_complete(path: str | Path) -> bool:
    """Whether the file was finished (footer and closing magic present): False after a crash."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        if f.tell() < 8 + 37:
            return False
        f.seek(-8, 2)
        return f.read(8) == b"\x89MCAP0\r\n"


def default_log_path(log_dir: str, fleet: str, kind: str = "run") -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    return Path(log_dir) / f"{fleet}-{kind}-{stamp}.mcap"
