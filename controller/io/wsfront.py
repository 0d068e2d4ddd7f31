"""The live view's WebSocket endpoint for every Foxglove client: the current one and the legacy.

foxglove-sdk's server (0.30) accepts only the ``foxglove.sdk.v1`` subprotocol (and ``.v1.1``),
with no option for more; Lichtblick, older Foxglove Studio and ``@foxglove/ws-protocol``'s
default client offer only the legacy ``foxglove.websocket.v1`` and got HTTP 400. This front, on
``viz.port``, accepts both: a client offering a ``foxglove.sdk.v1*`` subprotocol is relayed
frame by frame to foxglove-sdk's own server (on a loopback port of its own: the current
protocol stays foxglove-sdk's), a client offering only ``foxglove.websocket.v1`` is served here.

The legacy protocol as served (``foxglove/ws-protocol`` v1 spec, the subset the scene needs:
JSON channels only): ``serverInfo`` on connect, ``advertise`` of every channel (``encoding``
"json", ``schemaName``, the JSON Schema text as ``schema``, ``schemaEncoding``
"jsonschema"), then ``subscribe``/``unsubscribe`` from the client and binary message data
(opcode 1, uint32 subscription id, uint64 log time in ns, little endian, then the payload).
Each legacy client has a bounded queue: a viewer that does not keep up loses messages (counted
in ``dropped``), it never holds up the others or the recorder.

Built on ``websockets`` (asyncio, one thread of its own) rather than the ``foxglove-websocket``
package: that one is Foxglove's superseded server (foxglove-sdk replaced it) and we need a
front for the current protocol on the same port anyway.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from websockets.asyncio.client import connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed, NegotiationError

log = logging.getLogger(__name__)

SDK = ("foxglove.sdk.v1", "foxglove.sdk.v1.1")  # foxglove-sdk's own (the current app)
LEGACY = "foxglove.websocket.v1"  # ws-protocol v1 (Lichtblick, older Foxglove Studio)
SUBPROTOCOLS = (*SDK, LEGACY)
CLIENT_QUEUE = 1024  # messages a legacy client may have waiting before it loses some
_DATA = struct.Struct("<BIQ")  # opcode 1, subscription id, log time ns


def select_subprotocol(offered: list[str]) -> str:
    """The subprotocol to answer a client offering ``offered``: the first foxglove-sdk one it
    offers, else the legacy one; NegotiationError (HTTP 400) when it offers neither."""
    for p in offered:
        if p in SDK:
            return p
    if LEGACY in offered:
        return LEGACY
    raise NegotiationError(f"no supported subprotocol (offered {offered}; served {SUBPROTOCOLS})")


@dataclass
class _Channel:
    id: int
    topic: str
    schema_name: str
    schema: str

    def advert(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "topic": self.topic,
            "encoding": "json",
            "schemaName": self.schema_name,
            "schema": self.schema,
            "schemaEncoding": "jsonschema",
        }


@dataclass(eq=False)  # hashed by identity: a set of the connected clients
class _Client:
    ws: ServerConnection
    out: asyncio.Queue = field(default_factory=lambda: asyncio.Queue(CLIENT_QUEUE))
    subs: dict[int, int] = field(default_factory=dict)  # subscription id -> channel id


class Front:
    """The WebSocket endpoint on ``host:port`` (0: any free port), relaying foxglove-sdk clients
    to ``inner_port`` and serving legacy ones from :meth:`publish`."""

    def __init__(self, host: str, port: int, inner_port: int, name: str) -> None:
        self.host = host
        self.inner_port = inner_port
        self.name = name
        self.session_id = str(time.time_ns())
        self.dropped = 0  # legacy client messages lost to a full queue
        self.legacy_clients = 0
        self._channels: dict[str, _Channel] = {}
        self._ids = itertools.count(1)
        self._clients: set[_Client] = set()
        self._loop = asyncio.new_event_loop()
        self._server: Any = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(port,), name="viz-front",
                                        daemon=True)  # fmt: skip
        self._thread.start()
        self._started.wait(10)
        if self._error is not None:
            raise self._error
        self.port = int(self._server.sockets[0].getsockname()[1])

    # -- the loop's thread
    def _run(self, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(self._serve(port))
        except BaseException as exc:  # noqa: BLE001 - reported to the constructor
            self._error = exc
            self._started.set()
            return
        self._started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._loop.shutdown_asyncgens())
        self._loop.close()

    async def _serve(self, port: int) -> Any:
        return await serve(
            self._handle,
            self.host,
            port,
            subprotocols=list(SUBPROTOCOLS),
            select_subprotocol=lambda conn, offered: select_subprotocol(list(offered)),
            compression=None,
            max_size=None,
        )

    async def _handle(self, ws: ServerConnection) -> None:
        if ws.subprotocol in SDK:
            await self._relay(ws)
        else:
            await self._legacy(ws)

    async def _relay(self, ws: ServerConnection) -> None:
        """A foxglove-sdk client: every frame both ways to and from foxglove-sdk's server."""
        url = f"ws://127.0.0.1:{self.inner_port}"
        async with connect(url, subprotocols=[ws.subprotocol], compression=None,
                           max_size=None) as inner:  # fmt: skip

            async def pump(src, dst) -> None:
                try:
                    async for m in src:
                        await dst.send(m)
                except ConnectionClosed:
                    pass

            tasks = [asyncio.create_task(pump(ws, inner)), asyncio.create_task(pump(inner, ws))]
            try:
                await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for t in tasks:
                    t.cancel()

    async def _legacy(self, ws: ServerConnection) -> None:
        client = _Client(ws)
        info = {
            "op": "serverInfo",
            "name": self.name,
            "capabilities": [],
            "supportedEncodings": [],
            "metadata": {},
            "sessionId": self.session_id,
        }
        await ws.send(json.dumps(info))
        if self._channels:
            channels = [c.advert() for c in self._channels.values()]
            await ws.send(json.dumps({"op": "advertise", "channels": channels}))
        self._clients.add(client)
        self.legacy_clients += 1
        writer = asyncio.create_task(self._write(client))
        try:
            async for m in ws:
                if isinstance(m, str):
                    self._on_request(client, m)
        except ConnectionClosed:
            pass
        finally:
            self._clients.discard(client)
            writer.cancel()

    def _on_request(self, client: _Client, text: str) -> None:
        try:
            req = json.loads(text)
            op = req.get("op")
            if op == "subscribe":
                for s in req["subscriptions"]:
                    client.subs[int(s["id"])] = int(s["channelId"])
            elif op == "unsubscribe":
                for sid in req["subscriptionIds"]:
                    client.subs.pop(int(sid), None)
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            log.warning("live view: a bad request from a legacy client: %s", exc)

    async def _write(self, client: _Client) -> None:
        try:
            while True:
                await client.ws.send(await client.out.get())
        except ConnectionClosed:
            pass

    def _offer(self, client: _Client, frame: str | bytes) -> None:
        try:
            client.out.put_nowait(frame)
        except asyncio.QueueFull:
            self.dropped += 1

    def _publish(self, topic: str, schema: str, schema_data: bytes, payload: bytes,
                 log_ns: int) -> None:  # fmt: skip
        ch = self._channels.get(topic)
        if ch is None:
            ch = _Channel(next(self._ids), topic, schema, schema_data.decode("utf-8"))
            self._channels[topic] = ch
            advert = json.dumps({"op": "advertise", "channels": [ch.advert()]})
            for c in self._clients:
                self._offer(c, advert)
        for c in self._clients:
            for sid, cid in c.subs.items():
                if cid == ch.id:
                    self._offer(c, _DATA.pack(1, sid, log_ns) + payload)

    # -- any thread
    def publish(
        self, topic: str, schema: str, schema_data: bytes, payload: bytes, log_ns: int
    ) -> None:
        """One message of ``topic`` (JSON ``payload``, its JSON Schema ``schema_data`` named
        ``schema``) for the legacy clients; never blocks."""
        self._loop.call_soon_threadsafe(self._publish, topic, schema, schema_data, payload, log_ns)

    def close(self) -> None:
        if self._server is None or self._loop.is_closed():
            return

        async def stop() -> None:
            self._server.close()
            await self._server.wait_closed()

        try:
            asyncio.run_coroutine_threadsafe(stop(), self._loop).result(10)
        except Exception:  # noqa: BLE001 - closing anyway
            log.exception("live view: closing the WebSocket endpoint")
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)
