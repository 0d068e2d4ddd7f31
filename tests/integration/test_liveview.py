"""The live view (``--viz``): the recorder's messages served over a Foxglove WebSocket on
127.0.0.1, read here by a plain WebSocket client speaking the Foxglove protocol, once with the
current subprotocol and once with the legacy one; a full queue drops (and counts) instead of
blocking."""

from __future__ import annotations

import asyncio
import json
import struct
import threading

import pytest
import websockets

from controller import wire
from controller.io.liveview import LiveView
from controller.runtime.recording import open_recorder
from controller.scene.builder import schema
from tests.support.config import make_config
from tests.support.foxglove import errors

# the current Foxglove app's (foxglove-sdk's server) and the legacy one's (Lichtblick, older
# Foxglove Studio, @foxglove/ws-protocol's default client): each client below offers only one
CURRENT, LEGACY = "foxglove.sdk.v1", "foxglove.websocket.v1"
SUBSCRIBED = ("/scene/stats", "/tf", "/scene/robots")


def feed_ticks(rec, cfg, t0: float, n: int) -> None:
    """``n`` controller ticks at 20 Hz: every robot's state and the object's."""
    for k in range(n):
        t = t0 + 0.05 * k
        for r in cfg.robots:
            st = wire.RobotState(t=t, id=r.id, x=r.start[0] + 0.1 * t, y=r.start[1], theta=0)
            rec.on_sample(wire.key("robot_state", cfg.fleet.name, id=r.id), wire.encode(st), t)
        obj = wire.ObjectState(t=t, x=2.0, y=3.0, theta=0.0)
        rec.on_sample(wire.key("object_state", cfg.fleet.name), wire.encode(obj), t)


async def read_until(ws, pred, timeout: float = 20.0):
    """Messages until ``pred(msg)`` holds (a handshake with a deadline)."""
    async with asyncio.timeout(timeout):
        while True:
            msg = await ws.recv()
            if pred(msg):
                return msg


@pytest.mark.parametrize("subprotocol", [CURRENT, LEGACY])
def test_a_websocket_client_sees_the_scene(tmp_path, subprotocol):
    """A client offering only ``subprotocol`` connects, is advertised the scene's JSON channels,
    subscribes, and receives messages valid against the vendored Foxglove JSON Schemas (strictly:
    no unknown field) with the log's own time."""
    cfg = make_config({"viz": {"port": 0}})
    rec = open_recorder(cfg, tmp_path / "v.mcap", "run/ideal", sim_time=True, viz=True)
    view = rec.taps[0]
    got: dict[str, list] = {}
    channels: dict[str, dict] = {}

    async def client() -> None:
        url = f"ws://127.0.0.1:{view.port}"
        async with websockets.connect(url, subprotocols=[subprotocol]) as ws:
            assert ws.subprotocol == subprotocol
            info = json.loads(await read_until(ws, lambda m: "serverInfo" in str(m)))
            assert info["op"] == "serverInfo"
            feed_ticks(rec, cfg, 0.05, 10)  # channels are advertised as their first message goes

            def advertised(m) -> bool:
                if isinstance(m, str) and json.loads(m).get("op") == "advertise":
                    channels.update({c["topic"]: c for c in json.loads(m)["channels"]})
                return set(SUBSCRIBED) <= set(channels)

            await read_until(ws, advertised)
            subs = dict(enumerate(SUBSCRIBED, start=1))
            await ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [
                            {"id": i, "channelId": channels[t]["id"]} for i, t in subs.items()
                        ],
                    }
                )
            )

            def data(m) -> None:
                if isinstance(m, bytes) and m[0] == 1:  # opcode 1: message data
                    sub, ns = struct.unpack_from("<IQ", m, 1)
                    got.setdefault(subs[sub], []).append((ns, json.loads(m[13:])))

            # the server takes the subscription in its own time (no answer in the protocol):
            # the fleet keeps ticking until every channel's messages come (bounded)
            t = 1.0
            async with asyncio.timeout(20):
                while len(got) < len(SUBSCRIBED):
                    feed_ticks(rec, cfg, t, 4)
                    t += 0.2
                    try:
                        data(await asyncio.wait_for(ws.recv(), 0.5))
                    except TimeoutError:
                        pass

    try:
        asyncio.run(client())
    finally:
        rec.close()
    assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert channels["/scene/robots"]["schemaName"] == "foxglove.SceneUpdate"
    for topic in SUBSCRIBED:
        c = channels[topic]
        assert c["encoding"] == "json"
        # the schema travels with the channel, as the JSON Schema Foxglove decodes against
        assert json.loads(c["schema"]) == schema(c["schemaName"]), topic
        for _, msg in got[topic]:
            assert not errors(c["schemaName"], msg), (topic, errors(c["schemaName"], msg))
    stats_ns, stats = got["/scene/stats"][0]
    assert stats["robots"] == len(cfg.robots)
    ns, tf = got["/tf"][0]
    assert {t["child_frame_id"] for t in tf["transforms"]} >= {f"robot/{r}" for r in cfg.robot_ids}
    robots = got["/scene/robots"][-1][1]
    assert {e["id"] for e in robots["entities"]} >= {f"robot/{r}" for r in cfg.robot_ids}
    # served with the log's own time: sim time on the sim epoch
    assert abs(ns / 1e9 - (946_684_800.0 + stats["t"])) < 0.2
    assert view.sent > 0 and rec.drops()["viz_dropped"] == 0


def test_a_client_offering_neither_subprotocol_is_refused():
    view = LiveView(port=0)

    async def client() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{view.port}", subprotocols=["mqtt"]):
            pass

    try:
        with pytest.raises(websockets.exceptions.InvalidStatus, match="400"):
            asyncio.run(client())
    finally:
        view.close()


def test_a_full_queue_drops_and_counts_instead_of_blocking():
    view = LiveView(port=0, queue_size=16)
    release = threading.Event()
    taken = threading.Event()

    class Stuck:
        def log(self, payload, log_time=None):
            taken.set()
            release.wait(30)

    view._channel = lambda *a: Stuck()  # a viewer that does not keep up
    try:
        view.offer("/x", "", b"", b"{}", 0)
        assert taken.wait(10)  # the server thread holds one, stuck
        for _ in range(100):
            view.offer("/x", "", b"", b"{}", 0)  # never blocks
        assert view.dropped == 100 - 16 and view.drops() == {"viz_dropped": 84}
    finally:
        release.set()
        view.close()
