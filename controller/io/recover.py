"""``fleet log recover``: a valid, indexed copy of an MCAP file cut short by a crash.

A recorder killed without warning leaves its chunks (flushed every ``log.flush_interval``) but
no summary, index or footer, so readers that seek the footer (``mcap.reader.make_reader``, most
tools) fail before the first message. The copy holds every record read before the cut (schemas,
channels, metadata, attachments, messages, with their times and sequence numbers) and is
finished properly: summary, statistics, chunk and message indexes, footer.
"""

from __future__ import annotations

import logging
import struct
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from controller.config import InputError
from controller.io.recorder import PROFILE, log_is_complete

log = logging.getLogger(__name__)
CUT = (McapError, EOFError, struct.error, ZstdError)


def recover(src: str | Path, dst: str | Path) -> dict[str, Any]:
    """Copy ``src`` (complete or cut) into a finished, indexed ``dst``. Returns what was copied:
    ``input_complete``, ``messages``, ``channels``, ``schemas``, ``metadata``, ``attachments``,
    ``start_s`` and ``end_s`` (log time of the first and last message), ``seconds`` (their
    span), ``cut`` (why reading stopped early, or None), ``bytes`` (of the copy)."""
    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise InputError(f"{src}: no such file")
    if dst.exists() and src.resolve() == dst.resolve():
        raise InputError(f"{dst}: the copy must not overwrite the input")
    dst.parent.mkdir(parents=True, exist_ok=True)
    cut = None
    with open(src, "rb") as f, open(dst, "wb") as out:
        copy = _Copy(Writer(out, compression=CompressionType.ZSTD))
        try:
            for rec in StreamReader(f).records:
                copy.add(rec)
        except CUT as exc:
            cut = type(exc).__name__ + (f": {exc}" if str(exc) else "")
            log.info("%s: read up to the cut (%s)", src, cut)
        copy.finish()
    first, last = copy.first, copy.last
    return {
        "input": str(src),
        "output": str(dst),
        "input_complete": log_is_complete(src),
        **copy.counts,
        "start_s": None if first is None else first / 1e9,
        "end_s": None if last is None else last / 1e9,
        "seconds": 0.0 if first is None or last is None else (last - first) / 1e9,
        "cut": cut,
        "bytes": dst.stat().st_size,
    }


class _Copy:
    """Records into a writer, with the schema and channel ids mapped to the copy's."""

    def __init__(self, writer: Writer) -> None:
        self.w = writer
        self.started = False
        self.schemas: dict[int, int] = {0: 0}
        self.channels: dict[int, int] = {}
        self.counts = {"messages": 0, "channels": 0, "schemas": 0, "metadata": 0}
        self.counts["attachments"] = 0
        self.first: int | None = None
        self.last: int | None = None

    def _start(self, profile: str = PROFILE, library: str = "fleet-controller") -> None:
        if not self.started:
            self.w.start(profile=profile, library=library)
            self.started = True

    def add(self, rec: Any) -> None:
        if isinstance(rec, Header):
            self._start(rec.profile or PROFILE, rec.library)
            return
        self._start()
        if isinstance(rec, Schema) and rec.id not in self.schemas:
            self.schemas[rec.id] = self.w.register_schema(rec.name, rec.encoding, rec.data)
            self.counts["schemas"] += 1
        elif isinstance(rec, Channel) and rec.id not in self.channels:
            sid = self.schemas.get(rec.schema_id, 0)
            self.channels[rec.id] = self.w.register_channel(
                rec.topic, rec.message_encoding, sid, rec.metadata
            )
            self.counts["channels"] += 1
        elif isinstance(rec, Message) and rec.channel_id in self.channels:
            self._message(rec)
        elif isinstance(rec, Metadata):
            self.w.add_metadata(rec.name, dict(rec.metadata))
            self.counts["metadata"] += 1
        elif isinstance(rec, Attachment):
            a = rec
            self.w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, bytes(a.data))
            self.counts["attachments"] += 1

    def _message(self, rec: Message) -> None:
        self.w.add_message(
            self.channels[rec.channel_id],
            log_time=rec.log_time,
            data=bytes(rec.data),
            publish_time=rec.publish_time,
            sequence=rec.sequence,
        )
        self.counts["messages"] += 1
        self.first = rec.log_time if self.first is None else min(self.first, rec.log_time)
        self.last = rec.log_time if self.last is None else max(self.last, rec.log_time)

    def finish(self) -> None:
        self._start()
        self.w.finish()
