"""Bus fuzz: garbage on every key the controller and the agents subscribe to.

Seeded (a numpy Generator, seed fixed): non-JSON, binary, JSON of the wrong shape, wrong field
types, NaN/inf, huge magnitudes, unknown and missing fields, deep nesting, a 10 MB payload, a
flood. Through the real decode step of the bus (``decode_payload``, what every zenoh callback
runs), the agent's command gate and the MCAP recorder; then one loopback zenoh test floods a live
agent and checks its watchdog still stops the robot.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import threading

import numpy as np
import pytest

from controller import wire
from controller.config import ZenohSection
from controller.io.bus import Bus, DecodeStats, Inbox, Received, decode_payload
from controller.io.recorder import McapRecorder, read_log
from controller.scene.builder import SceneBuilder
from drivers.agent import Agent, AgentCore, AgentParams
from drivers.base import Capabilities, LinkHealth
from tests.support.config import make_config
from tests.support.wait import wait_for

FLEET = "fz"
SEED = 20261117
# every topic a controller or an agent decodes (status replies and liveliness tokens aside)
TOPICS = [n for n, t in wire.TOPICS.items() if t.msg is not wire.Message and n != "status"]
PARTS = {"id": "r1", "what": "phase", "role": "robot"}


def key_of(topic: str) -> str:
    t = wire.TOPICS[topic]
    parts = {p: v for p, v in PARTS.items() if "{" + p + "}" in t.template}
    return t.key(FLEET, **parts)


def valid_payload(topic: str) -> dict:
    """A minimal valid message of the topic's type, as JSON data."""
    cls = wire.TOPICS[topic].msg
    obj: dict = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING:
            continue
        tp = wire._hints(cls)[f.name]
        obj[f.name] = {float: 1.0, int: 1, bool: False, str: "x"}.get(tp, {})
    wire.from_dict(cls, obj)  # valid indeed
    return obj


def garbage(topic: str, rng: np.random.Generator) -> list[bytes]:
    """Bad payloads for a topic: each must be refused by the decoder."""
    good = valid_payload(topic)
    cls = wire.TOPICS[topic].msg
    out: list[bytes] = [
        b"",
        b"not json",
        b"\xff\xfe\x00\x81garbage",
        bytes(rng.integers(0, 256, 64, dtype=np.uint8)),
        b"[1, 2, 3]",
        b"null",
        b'"a string"',
        b"{" * 100_000,  # nested far too deep
        b'{"t": NaN}',
        b'{"t": Infinity}',
        b'{"t": -Infinity}',
        json.dumps({**good, "unexpected": 1}).encode(),
        json.dumps({**good, "t": 1e300}).encode(),
        json.dumps({**good, "t": "soon"}).encode(),
        json.dumps({**good, "seq": 2**70}).encode(),
        json.dumps({**good, "seq": 1.5}).encode(),
        json.dumps({**good, "t": True}).encode(),
    ]
    for f in dataclasses.fields(cls):
        tp = wire._hints(cls)[f.name]
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            out.append(json.dumps({k: v for k, v in good.items() if k != f.name}).encode())
        if tp is float:
            huge = float(10.0 ** rng.uniform(4.5, 300)) * rng.choice([-1, 1])
            out.append(json.dumps({**good, f.name: huge}).encode())
            out.append(json.dumps({**good, f.name: [1.0]}).encode())
            out.append(json.dumps({**good, f.name: None}).encode())
            out.append(json.dumps({**good, f.name: "1.0"}).encode())
            out.append(json.dumps({**good, f.name: float("nan")}).encode())  # Python writes NaN
        elif tp is str:
            out.append(json.dumps({**good, f.name: 5}).encode())
            out.append(json.dumps({**good, f.name: "x" * 5000}).encode())
        elif tp is bool:
            out.append(json.dumps({**good, f.name: "yes"}).encode())
    return out


TEN_MB = b'{"t": 1.0, "x": "' + b"a" * (10 * 1024 * 1024) + b'"}'


@pytest.mark.parametrize("topic", TOPICS)
def test_decode_counts_and_drops_every_bad_payload(topic):
    rng = np.random.default_rng(SEED)
    stats = DecodeStats()
    box = Inbox()
    k = key_of(topic)
    bad = garbage(topic, rng) + [TEN_MB]
    good = json.dumps(valid_payload(topic)).encode()
    for payload in bad:
        for tp in (wire.TOPICS[topic].msg, None):  # by the subscription's type, by the key
            msg = decode_payload(FLEET, k, payload, tp, stats)
            assert msg is None, payload[:80]
    assert stats.counts == {k: 2 * len(bad)}
    msg = decode_payload(FLEET, k, good, None, stats)  # still works after all that
    assert isinstance(msg, wire.TOPICS[topic].msg)
    box.put(Received(0.0, k, msg))
    assert stats.total == 2 * len(bad) and len(box.drain()) == 1


def test_decode_flood_of_random_bytes_and_json():
    """20 000 random payloads across every key: none raises, every one is counted."""
    rng = np.random.default_rng(SEED)
    stats = DecodeStats()
    keys = [key_of(t) for t in TOPICS]
    n_bad = 0
    for i in range(20_000):
        k = keys[i % len(keys)]
        if i % 2:
            payload = bytes(rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8))
        else:  # JSON objects of random numbers on random known field names
            names = ["t", "seq", "x", "y", "theta", "vx", "vy", "wz", "ttl", "engaged"]
            obj = {
                str(rng.choice(names)): float(rng.standard_normal() * 10 ** rng.uniform(0, 12))
                for _ in range(int(rng.integers(0, 6)))
            }
            payload = json.dumps(obj).encode()
        msg = decode_payload(FLEET, k, payload, None, stats)
        n_bad += msg is None
    assert n_bad > 19_000 and stats.total == n_bad


def test_agent_gate_clamps_absurd_magnitudes_and_counts():
    caps = Capabilities("omni", True, 0.5, 2.0, 0.1)
    core = AgentCore(caps, cmd_ttl=0.3)
    rng = np.random.default_rng(SEED)
    limit = wire.MAX_ABS_SPEED
    n_clamped = 0
    for i in range(2_000):
        vx, vy, wz = (float(v) for v in rng.uniform(-limit, limit, 3))
        # what the codec lets through: the largest finite magnitudes it accepts
        cmd = wire.decode(wire.Twist2D, wire.encode(wire.Twist2D(t=i, vx=vx, vy=vy, wz=wz)))
        out = core.on_command(float(i), cmd)
        assert out is not None
        assert math.hypot(out.vx, out.vy) <= caps.max_speed + 1e-9
        assert abs(out.wz) <= caps.max_yaw_rate + 1e-12
        n_clamped += math.hypot(vx, vy) > caps.max_speed or abs(wz) > caps.max_yaw_rate
    assert core.counters.clamped == n_clamped > 1_900
    diff = AgentCore(Capabilities("diff", False, 0.5, 2.0, 0.1), cmd_ttl=0.3)
    out = diff.on_command(0.0, wire.Twist2D(t=0.0, vx=-99.0, vy=99.0, wz=-99.0))
    assert (out.vx, out.vy, out.wz) == (-0.5, 0.0, -2.0)
    assert diff.counters.clamped == 1 and diff.counters.vy_dropped == 1


def test_recorder_counts_bad_payloads_without_a_traceback(tmp_path, caplog):
    cfg = make_config({"fleet": {"name": FLEET}})
    rng = np.random.default_rng(SEED)
    path = tmp_path / "fz.mcap"
    n_bad = n_good = 0
    with caplog.at_level(logging.INFO):
        rec = McapRecorder(path, FLEET, 0.1, sim_epoch=0.0, scene=SceneBuilder(cfg))
        with rec:
            for topic in [t for t in TOPICS if wire.TOPICS[t].logged]:  # it skips the others
                k = key_of(topic)
                rec.on_sample(k, json.dumps({**valid_payload(topic), "t": 1.0}).encode(), 1.0)
                n_good += 1
                for payload in garbage(topic, rng):
                    rec.on_sample(k, payload, 1.0)
                    n_bad += 1
            rec.on_sample(key_of("robot_pose"), TEN_MB, 1.0)
            n_bad += 1
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"
    assert rec.bad_payloads == n_bad and rec.drops()["recorder_dropped"] == n_bad
    assert rec.written == n_good
    assert len([r for r in read_log(path) if r.topic.startswith(f"fleet/{FLEET}/")]) >= n_good


class CountingDriver:
    """A driver that records what the agent does to it."""

    def __init__(self) -> None:
        self.capabilities = Capabilities("omni", True, 0.5, 2.0, 0.1)
        self.sent: list[wire.Twist2D] = []
        self.stops = 0

    def connect(self, timeout: float) -> None:
        pass

    def send(self, cmd: wire.Twist2D) -> None:
        self.sent.append(cmd)

    def poll(self) -> list:
        return []

    def stop(self) -> None:
        self.stops += 1

    def health(self) -> LinkHealth:
        return LinkHealth(True, "", 0.0)

    def close(self) -> None:
        pass


def test_live_agent_keeps_its_watchdog_under_a_garbage_flood(port):
    """A live agent on loopback zenoh, flooded with garbage on its command and e-stop keys
    while a valid command stream runs and then stops: the valid commands get through (clamped),
    the garbage is counted, and the watchdog stops the robot within ttl + a tick."""
    ep = f"tcp/127.0.0.1:{port}"
    rng = np.random.default_rng(SEED)
    # each key its own topic's garbage: the e-stop's list holds {"t": 1.0} (an EStop without
    # `engaged`), which on the command key would be a valid zero Twist2D, not garbage
    junk = {t: garbage(t, rng) for t in ("robot_cmd", "estop")}
    with (
        Bus(ZenohSection(), FLEET, listen=[ep], connect=[]) as ctl,
        Bus(ZenohSection(), FLEET, listen=[], connect=[ep]) as rob,
    ):
        drv = CountingDriver()
        agent = Agent(rob, drv, AgentParams("r1", FLEET, cmd_ttl=0.3))
        cmd = ctl.publisher("robot_cmd", command=True, lossless=True, id="r1")
        wait_for(cmd.matching, 10, "agent subscribed")
        raw_cmd = ctl.session.declare_publisher(key_of("robot_cmd"))
        raw_estop = ctl.session.declare_publisher(key_of("estop"))
        stop_flood = threading.Event()
        sent = [0]

        def flood() -> None:
            i = 0
            while not stop_flood.is_set():
                pub, bad = (raw_cmd, junk["robot_cmd"]) if i % 3 else (raw_estop, junk["estop"])
                pub.put(bad[i % len(bad)])
                sent[0] += 1
                i += 1

        flooder = threading.Thread(target=flood, daemon=True)
        flooder.start()
        try:
            t = 0.0
            for k in range(10):  # a valid command stream, absurdly fast, amid the flood
                t = k * 0.05
                before = agent.commands_seen()
                cmd.put(wire.Twist2D(t=t, seq=k + 1, vx=50.0, wz=-40.0, ttl=0.3))
                wait_for(lambda b=before: agent.commands_seen() > b, 5, "command delivered")
                agent.step(t)
                assert drv.sent[-1].vx == 0.5 and drv.sent[-1].wz == -2.0
            last = t
            stops_before = drv.stops
            while t < last + 0.3 + 1e-9:  # the stream stops; the flood goes on
                t += 0.05
                agent.step(t)
                if t <= last + 0.3 - 1e-9:
                    assert drv.stops == stops_before, f"stopped early at {t - last:.2f} s"
            t += 0.05
            agent.step(t)
            assert drv.stops == stops_before + 1 and agent.counters.watchdog_stops == 1
            wait_for(lambda: rob.stats.total > 200, 10, "garbage received")
        finally:
            stop_flood.set()
            flooder.join(5)
        assert agent.counters.commands == 10 and agent.counters.clamped == 10
        assert not agent.core.estop  # no garbage e-stop latched or released anything
        assert rob.stats.total <= sent[0]
