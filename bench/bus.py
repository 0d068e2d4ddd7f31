"""Benchmark the zenoh bus between two processes on loopback. Prints one JSON object.

- round trip of a ~64-byte command: raw bytes echoed vs our codec (decode Twist2D, encode a
  PoseMeasurement reply), median and p99 in ms, same run, same processes;
- one-way throughput of commands (messages/s received by the other process).

Usage: python bench/bus.py [--n 2000]
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
from controller.io.bus import Bus  # noqa: E402

FLEET = "bench"


def child(endpoint: str) -> None:
    """Echo peer: raw ping -> raw pong; codec cmd -> decoded, re-encoded pose; counts floods."""
    import zenoh

    with Bus(ZenohSection(), FLEET, listen=[], connect=[endpoint]) as bus:
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
        "p99_ms": round(float(np.percentile(a, 99)), 4),
        "n": len(a),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child)
        return
    ep = f"tcp/127.0.0.1:{free_port()}"
    with Bus(ZenohSection(), FLEET, listen=[ep], connect=[]) as bus:
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
