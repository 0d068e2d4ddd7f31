"""The live view (``--viz``): the recorder's messages served over a Foxglove WebSocket on
127.0.0.1, read here by a plain WebSocket client speaking the Foxglove protocol; a full queue
drops (and counts) instead of blocking."""

from __future__ import annotations

import asyncio
import json
import struct
import threading

import websockets

from controller import wire
from controller.io.liveview import LiveView
from controller.runtime.recording import open_recorder
from tests.support.config import make_config
from tests.support.foxglove import errors

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


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


def test_a_websocket_client_sees_the_scene(tmp_path):
    cfg = make_config({"viz": {"port": 0}})
    rec = open_recorder(cfg, tmp_path / "v.mcap", "run/ideal", sim_time=True, viz=True)
    view = rec.taps[0]
    got: dict[str, list] = {}

    async def client() -> None:
        url = f"ws://127.0.0.1:{view.port}"
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS) as ws:
            info = json.loads(await read_until(ws, lambda m: "serverInfo" in str(m)))
            assert info["op"] == "serverInfo"
            feed_ticks(rec, cfg, 0.05, 10)  # channels are advertised as their first message goes
            channels: dict[str, dict] = {}

            def advertised(m) -> bool:
                if isinstance(m, str) and json.loads(m).get("op") == "advertise":
                    channels.update({c["topic"]: c for c in json.loads(m)["channels"]})
                return {"/scene/stats", "/tf", "/scene/robots"} <= set(channels)

            await read_until(ws, advertised)
            assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
            assert channels["/tf"]["encoding"] == "json"
            subs = {1: "/scene/stats", 2: "/tf"}
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
            # the fleet keeps ticking until both channels' messages come (bounded)
            t = 1.0
            async with asyncio.timeout(20):
                while len(got) < 2:
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
    stats_ns, stats = got["/scene/stats"][0]
    assert not errors("fleet.SceneStats", stats)
    assert stats["robots"] == len(cfg.robots)
    ns, tf = got["/tf"][0]
    assert not errors("foxglove.FrameTransforms", tf)
    assert {t["child_frame_id"] for t in tf["transforms"]} >= {f"robot/{r}" for r in cfg.robot_ids}
    # served with the log's own time: sim time on the sim epoch
    assert abs(ns / 1e9 - (946_684_800.0 + stats["t"])) < 0.2
    assert view.sent > 0 and rec.drops()["viz_dropped"] == 0


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
