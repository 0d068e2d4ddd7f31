"""The live view: the recorder's messages served over a Foxglove WebSocket on 127.0.0.1.

``fleet run --viz`` and ``fleet daemon --viz`` attach one to the recorder as a tap: every bus
message and every scene message the recorder writes is offered here too, so the Foxglove app
(Open connection → Foxglove WebSocket → ``ws://127.0.0.1:<port>``) shows a running fleet with the
same layout as a recorded one. ``offer`` never blocks: it puts into a bounded queue and counts
what a full queue drops; one thread of its own hands the messages to the foxglove-sdk server
and to the legacy clients' side of the endpoint.

The endpoint on ``viz.port`` is :mod:`controller.io.wsfront`'s: it accepts the current
``foxglove.sdk.v1`` (relayed to foxglove-sdk's server on a loopback port of its own) and the
legacy ``foxglove.websocket.v1`` (Lichtblick, older Foxglove Studio), served from the same feed.
"""

from __future__ import annotations

import logging
import queue
import threading
from typing import Any

import foxglove

from controller.io.wsfront import Front

log = logging.getLogger(__name__)

HOST = "127.0.0.1"  # loopback only (a lab machine's other interfaces are not ours to serve)


class LiveView:
    """A Foxglove WebSocket server fed from a bounded queue (see the module doc)."""

    def __init__(self, port: int = 8765, queue_size: int = 4096, name: str = "fleet") -> None:
        self._ctx = foxglove.Context()
        # foxglove-sdk's own server on a free loopback port: the front on ``port`` relays to it
        self._server = foxglove.start_server(name=name, host=HOST, port=0, context=self._ctx)
        try:
            self._front = Front(HOST, port, int(self._server.port), name)
        except BaseException:
            self._server.stop()
            raise
        self._q: queue.Queue[tuple[str, str, bytes, bytes, int] | None] = queue.Queue(queue_size)
        self._channels: dict[str, Any] = {}
        self.sent = 0
        self.dropped = 0
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="live-view", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self._front.port

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.port}"

    def offer(
        self, topic: str, schema: str, schema_data: bytes, payload: bytes, log_time_ns: int
    ) -> None:
        """Queue one message for the viewers; dropped (and counted) when the queue is full."""
        try:
            self._q.put_nowait((topic, schema, schema_data, payload, log_time_ns))
        except queue.Full:
            self.dropped += 1

    def drops(self) -> dict[str, int]:
        return {"viz_dropped": self.dropped + self._front.dropped}

    def _channel(self, topic: str, schema: str, schema_data: bytes) -> Any:
        ch = self._channels.get(topic)
        if ch is None:
            sch = foxglove.Schema(name=schema, encoding="jsonschema", data=schema_data)
            ch = foxglove.Channel(
                topic, schema=sch if schema else None, message_encoding="json", context=self._ctx
            )
            self._channels[topic] = ch
        return ch

    def _run(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            topic, schema, schema_data, payload, log_ns = item
            try:
                self._channel(topic, schema, schema_data).log(payload, log_time=log_ns)
                self._front.publish(topic, schema, schema_data, payload, log_ns)
                self.sent += 1
            except Exception:  # noqa: BLE001 - a viewer problem never stops the recorder
                self.dropped += 1
                log.exception("live view: could not serve a message on %s", topic)

    def close(self) -> None:
        """Serve what is queued, then stop the server."""
        if self._closed:
            return
        self._closed = True
        self._q.put(None)  # blocks only while the queue is full: the thread is draining it
        self._thread.join(timeout=10)
        self._front.close()
        self._server.stop()
