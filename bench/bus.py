"""Benchmark the zenoh bus between two processes on loopback. Prints one JSON object.

- round trip of a ~64-byte command: raw bytes echoed vs our codec (decode Twist2D, encode a
  PoseMeasurement reply), median and p99 in ms, same run, same processes;
- one-way throughput of commands (messages/s received by the other process).

``--flood``: the daemon's tick (``ControllerNode.tick`` with a 20 Hz rate keeper, hold mission,
4 robots) while another process puts poses on the robots' keys: the normal rate (30 Hz per
robot), 10x that, as fast as it can, the normal rate plus 4 MiB payloads (10 Hz per key), and
one robot as fast as it can (``one_robot_max``, the others at the normal rate). Each case runs
three times in this process, interleaved, each with the daemon's recorder tap (a no-op):
``before`` is the bus before issue 22 (decoding on zenoh's thread into unbounded inboxes, 4 MiB
limit), ``after`` a callback per sample (size checked first, a rate limit per key, decoder
thread, inboxes bounded per key), ``rings`` the daemon today (issue 31 5c: the poses in a zenoh
ring per key, read at each tick, never a Python callback). Tick p50/p99/max (ms), late ticks,
poses taken in, drops, the p99 ratios, and the load average.

Usage: python bench/bus.py [--n 2000] | python bench/bus.py --flood [--seconds 4] [--cases A,B]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controller import wire  # noqa: E402
from controller.config import ZenohSection  # noqa: E402
from controller.io.bus import Bus, Inbox, Received, decode_payload  # noqa: E402

FLEET = "bench"


# the round trips run back to back, faster than a key's rate limit in an inbox (zenoh.key_rate_hz,
# 1 kHz: a robot's poses come at 30-100 Hz): the limit off, so the codec is what is measured
UNLIMITED = ZenohSection(key_rate_hz=0)


def child(endpoint: str) -> None:
    """Echo peer: raw ping -> raw pong; codec cmd -> decoded, re-encoded pose; counts floods."""
    import zenoh

    with Bus(UNLIMITED, FLEET, listen=[], connect=[endpoint]) as bus:
        s = bus.session
        raw_pong = s.declare_publisher("bench/raw/pong", express=True)
        pose_pub = bus.publisher("robot_pose", command=True, id="b1")
        count = [0]

        def on_raw(sample):
            raw_pong.put(sample.payload.to_bytes())

        def on_cmd(sample):
            cmd = wire.decode(wire.Twist2D, sample.payload.to_bytes())
            pose_pub.put(wire.PoseMeasurement(t=cmd.t, seq=cmd.seq, x=cmd.vx, y=cmd.vy, theta=0.0))

        def on_flood(sample):
            count[0] += 1

        def on_count(query):
            query.reply("bench/count", str(count[0]).encode())

        handles = [
            s.declare_subscriber("bench/raw/ping", on_raw),
            s.declare_subscriber(bus.key("robot_cmd", id="b1"), on_cmd),
            s.declare_subscriber("bench/flood", on_flood),
            s.declare_queryable("bench/count", on_count),
            s.liveliness().declare_token("bench/alive"),
        ]
        sys.stdin.read()  # run until the parent closes our stdin
        del handles, zenoh


def free_port() -> int:
    with socket.socket() as so:
        so.bind(("127.0.0.1", 0))
        return int(so.getsockname()[1])


def stats_ms(samples: list[float]) -> dict[str, float]:
    a = np.asarray(samples) * 1e3
    return {
        "median_ms": round(float(np.median(a)), 4),
        "p50_ms": round(float(np.percentile(a, 50)), 4),
        "p99_ms": round(float(np.percentile(a, 99)), 4),
        "n": len(a),
    }


# --------------------------------------------------------------------------- --flood

ROBOTS = 4
POSE_HZ = 30.0  # the normal pose rate of a robot (sim.pose_rate_hz)
BIG = 4 * 1024 * 1024 - 1024  # under the old 4 MiB limit: the old bus decoded it all
CASES = {  # name: (pose rate multiplier, 0 = as fast as possible; big payloads per s per key)
    "normal": (1.0, 0.0),
    "poses_10x": (10.0, 0.0),
    "poses_max": (0.0, 0.0),
    "big_4mib": (1.0, 10.0),
    "one_robot_max": (0.0, 0.0),  # r1 alone, as fast as it can (the others at the normal rate)
}


class BeforeBus(Bus):
    """The bus before issue 22 (same session, same codec): every sample copied and decoded on
    zenoh's thread into an unbounded inbox; the codec's 4 MiB limit only."""

    def inbox(self, *, lossless: bool = False, waker=None) -> Inbox:
        return Inbox(waker=waker)

    def subscribe(self, key_expr, msg_type, inbox=None, on_message=None, lossless=False):
        box = inbox if inbox is not None else Inbox()
        self._inboxes.append(box)
        fleet, stats = self.fleet, self.stats

        def callback(sample) -> None:
            k = str(sample.key_expr)
            msg = decode_payload(fleet, k, sample.payload.to_bytes(), msg_type, stats)
            if msg is not None:
                box.put(Received(time.time(), k, msg))

        self._handles.append(self.session.declare_subscriber(key_expr, callback))
        return box


def flood_child(endpoint: str, case: str, seconds: float) -> None:
    """Robot-side flooder: liveliness tokens for r1..rN, then poses (and big payloads)."""
    import zenoh

    from controller.io.ratekeeper import Ratekeeper

    mult, big_hz = CASES[case]
    big = b'{"t": 0.0, "seq": 0, "x": 0, "y": 0, "theta": 0, "pad": "' + b"x" * BIG + b'"}'
    ids = [f"r{i + 1}" for i in range(ROBOTS)]
    with Bus(ZenohSection(), FLEET, listen=[], connect=[endpoint]) as bus:
        pubs = [
            bus.session.declare_publisher(
                bus.key("robot_pose", id=r), congestion_control=zenoh.CongestionControl.BLOCK
            )
            for r in ids
        ]
        for r in ids:
            bus.declare_alive("robot", r)
        one = case == "one_robot_max"
        rk = Ratekeeper(POSE_HZ * mult) if mult else None
        every = int(round(POSE_HZ * mult / big_hz)) if big_hz else 0
        end = time.monotonic() + seconds
        k = 0
        next_normal = time.monotonic()
        seqs = [0] * len(pubs)  # each robot's own sequence
        while time.monotonic() < end:
            if rk is not None:
                rk.keep_time()
            k += 1
            now = time.time()
            normal = time.monotonic() >= next_normal
            if normal:
                next_normal += 1.0 / POSE_HZ
            for i, pub in enumerate(pubs):
                if one and i > 0 and not normal:
                    continue  # the others at their normal rate
                seqs[i] += 1
                m = wire.PoseMeasurement(t=now, seq=seqs[i], x=1.0 + i, y=1.0, theta=0.0)
                pub.put(wire.encode(m))
                if every and k % every == 0:
                    pub.put(big)


def flood_run(bus_cls, case: str, seconds: float, rings: bool = False) -> dict:
    """One case against one bus: the node's ticks while the child floods, with the daemon's
    recorder tap (a no-op here): over the fleet's every key, or (``rings``, the daemon today)
    the poses read from zenoh rings at each tick and the tap over the other topics."""
    import tomllib

    from controller.config import parse_config
    from controller.io.ratekeeper import Ratekeeper
    from controller.mission.basic import HoldMission
    from controller.runtime.daemon import RING_TOPICS
    from controller.runtime.node import ControllerNode
    from controller.runtime.wiring import make_estimator

    ep = f"tcp/127.0.0.1:{free_port()}"
    with open(ROOT / "fleet.toml", "rb") as f:
        data = tomllib.load(f)
    proto = dict(data["robots"][0], kind="omni", driver="sim")
    data["robots"] = [dict(proto, id=f"r{i + 1}", start=[1.0 + i, 1.0, 0.0]) for i in range(ROBOTS)]
    data["object"].pop("goal", None)
    data["fleet"]["name"] = FLEET
    data["zenoh"] = {"mode": "peer", "listen": [ep], "connect": []}
    cfg = parse_config(data, "bench")
    with bus_cls(cfg.zenoh, FLEET) as bus:

        def tap(key: str, payload: bytes, t: float) -> None:
            pass

        if rings:
            bus.subscribe_raw_topics(tap, limit=True, skip=RING_TOPICS)
        else:
            bus.subscribe_raw(wire.fleet_prefix(FLEET), tap, limit=True)
        node = ControllerNode(cfg, bus, HoldMission(ROBOTS), make_estimator(cfg), rings=rings,
                              pose_tap=tap if rings else None)  # fmt: skip
        proc = subprocess.Popen(
            [sys.executable, __file__, "--flood-child", ep, case, str(seconds + 3.0)],
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
        try:
            deadline = time.monotonic() + 30
            while not node.present.all():  # the child's tokens: its publishers are declared
                if time.monotonic() > deadline:
                    raise SystemExit("flood child did not come up")
                time.sleep(0.05)  # polling a flag set on zenoh's thread
            rk = Ratekeeper(cfg.fleet.rate_hz)
            ticks: list[float] = []
            lags: list[float] = []
            poses0 = node.counters.poses
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                rk.keep_time()
                lags.append(rk.last_lag)
                t0 = time.perf_counter()
                node.tick(time.time())
                ticks.append(time.perf_counter() - t0)
            out = {
                **{f"tick_{k}": v for k, v in stats_ms(ticks).items()},
                "tick_max_ms": round(max(ticks) * 1e3, 3),
                "lag_max_ms": round(max(lags) * 1e3, 3),
                "late_ticks": rk.lagged,
                "skipped_ticks": rk.skipped,
                "poses_taken": node.counters.poses - poses0,
                "drops": bus.drops(),
            }
        finally:
            proc.kill()
            proc.wait(timeout=30)
    return out


def flood_main(seconds: float, cases: list[str]) -> None:
    out: dict = {"robots": ROBOTS, "pose_hz": POSE_HZ, "seconds": seconds, "cases": {}}
    for case in cases:
        res = {
            "before": flood_run(BeforeBus, case, seconds),
            "after": flood_run(Bus, case, seconds),
            "rings": flood_run(Bus, case, seconds, rings=True),
        }
        b, a, r = (res[k]["tick_p99_ms"] for k in ("before", "after", "rings"))
        res["tick_p99_after_over_before"] = round(a / b, 3) if b else None
        res["tick_p99_rings_over_after"] = round(r / a, 3) if a else None
        out["cases"][case] = res
    out["loadavg"] = [round(v, 2) for v in os.getloadavg()]
    print(json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--flood", action="store_true", help="the daemon's tick under floods")
    ap.add_argument("--seconds", type=float, default=4.0, help="per --flood case and bus")
    ap.add_argument("--cases", default=",".join(CASES), help="--flood cases, comma-separated")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--flood-child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child)
        return
    if args.flood_child:
        flood_child(args.flood_child[0], args.flood_child[1], float(args.flood_child[2]))
        return
    if args.flood:
        flood_main(args.seconds, args.cases.split(","))
        return
    ep = f"tcp/127.0.0.1:{free_port()}"
    with Bus(UNLIMITED, FLEET, listen=[ep], connect=[]) as bus:
        s = bus.session
        present = threading.Event()
        s.liveliness().declare_subscriber("bench/alive", lambda smp: present.set(), history=True)
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", ep],
            stdin=subprocess.PIPE,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
        try:
            if not present.wait(30):
                raise SystemExit("bench child did not come up")
            import zenoh

            # raw round trip
            got = threading.Event()
            s.declare_subscriber("bench/raw/pong", lambda smp: got.set())
            ping = s.declare_publisher("bench/raw/ping", express=True)
            cmd_example = wire.encode(wire.Twist2D(t=12345.678, seq=1, vx=0.25, vy=0.0, wz=0.1))
            raw_payload = b"x" * len(cmd_example)
            # codec round trip
            poses = bus.subscribe_topic("robot_pose", id="b1")
            cmd = bus.publisher("robot_cmd", command=True, id="b1")

            def raw_once() -> float:
                got.clear()
                t0 = time.perf_counter()
                ping.put(raw_payload)
                if not got.wait(2.0):
                    raise RuntimeError("raw pong lost")
                return time.perf_counter() - t0

            def codec_once(i: int) -> float:
                t0 = time.perf_counter()
                cmd.put(wire.Twist2D(t=float(i), seq=i, vx=0.25, wz=0.1))
                item = poses.get(timeout=2.0)
                if item is None or item.msg.seq != i:
                    raise RuntimeError("codec pong lost")
                return time.perf_counter() - t0

            for i in range(200):  # warm-up
                raw_once()
                codec_once(i)
            raw_rt, codec_rt = [], []
            for i in range(args.n):  # interleaved so both see the same machine load
                raw_rt.append(raw_once())
                codec_rt.append(codec_once(1000 + i))

            # one-way throughput (reliable, blocking congestion control: nothing dropped)
            flood = s.declare_publisher(
                "bench/flood", congestion_control=zenoh.CongestionControl.BLOCK
            )
            n_flood = 200_000
            t0 = time.perf_counter()
            for _ in range(n_flood):
                flood.put(cmd_example)
            received = 0
            deadline = time.perf_counter() + 30
            while time.perf_counter() < deadline:
                reply = next(iter(s.get("bench/count", timeout=2.0)))
                received = int(reply.ok.payload.to_bytes())
                if received >= n_flood:
                    break
            elapsed = time.perf_counter() - t0
            # our codec's own cost per command, encode + decode
            t1 = time.perf_counter()
            for i in range(20000):
                wire.decode(wire.Twist2D, wire.encode(wire.Twist2D(t=float(i), seq=i, vx=0.1)))
            codec_us = (time.perf_counter() - t1) / 20000 * 1e6
        finally:
            proc.stdin.close()
            proc.wait(timeout=30)
    raw, codec = stats_ms(raw_rt), stats_ms(codec_rt)
    out = {
        "payload_bytes": len(cmd_example),
        "round_trip_raw": raw,
        "round_trip_codec": codec,
        "codec_over_raw_median": round(codec["median_ms"] / raw["median_ms"], 3),
        "codec_encode_decode_us": round(codec_us, 2),
        "throughput_msgs_per_s": round(received / elapsed),
        "throughput_received": received,
        "throughput_sent": n_flood,
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
