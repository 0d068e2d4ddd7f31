"""MAVLink path benchmark over UDP loopback; prints one JSON object on stdout.

- ``latency_ms``: command-to-vehicle latency, from ``MavlinkDriver.send`` to the emulator's
  thread having decoded the SET_POSITION_TARGET_LOCAL_NED (median, p99), against a raw pymavlink
  baseline in the same process: one ``udpin`` connection sends the same message to a receiver
  thread that waits in ``select`` and decodes it with ``recv_msg`` (the same wake-up path as the
  emulator). ``ratio`` = adapter median / baseline median.
- ``pose_rate_hz``: PoseMeasurements per second received by each driver for 1 and 10 robots
  sharing one ``udpin`` port (each emulator in its own thread, telemetry asked at
  ``telemetry_hz``, a world thread stepping an ideal world in real time, the drivers polled at
  100 Hz like agents): median and minimum over robots.

Usage: python bench/mavlink.py [--samples N] [--seconds S]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import select
import socket
import sys
import threading
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

from controller.config import FleetConfig, parse_config  # noqa: E402
from controller.wire import Twist2D  # noqa: E402
from drivers.mavlink import convert as mc  # noqa: E402
from drivers.mavlink.driver import MavlinkDriver
from drivers.mavlink.link import LinkPool
from sim_backend.ideal import IdealWorld  # noqa: E402
from sim_backend.mavlink_vehicle import VehicleEmulator  # noqa: E402


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_config(n: int, port: int) -> FleetConfig:
    robots = [
        {
            "id": f"r{i}",
            "kind": "diff",
            "start": [1.0 + 0.5 * (i % 10), 1.0 + 0.5 * (i // 10), 0.0],
            "driver": "mavlink",
            "url": f"udpin:127.0.0.1:{port}",
            "system_id": i + 1,
            "profile": "ardurover",
        }
        for i in range(n)
    ]
    return parse_config(
        {
            "fleet": {"name": "bench"},
            "object": {
                "polygon": [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]],
                "start": [8.0, 8.0, 0.0],
                "goal": [9.0, 9.0, 0.0],
                "motion": {"kind": "static"},
            },
            "sim": {"backend": "ideal", "timestep": 0.01},
            "robots": robots,
        }
    )


def stats_ms(x: list[float]) -> dict[str, float]:
    a = np.asarray(x) * 1e3
    return {
        "median": round(float(np.median(a)), 4),
        "p99": round(float(np.percentile(a, 99)), 4),
        "n": len(a),
    }


def adapter_latency(samples: int) -> list[float]:
    port = free_udp_port()
    cfg = make_config(1, port)
    world = IdealWorld(cfg)
    got = threading.Event()
    stamp: dict[str, float] = {}

    def listener(m) -> None:
        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            stamp["t"] = time.perf_counter()
            stamp["vx"] = m.vx
            got.set()

    emu = VehicleEmulator(world, cfg.robots[0], listener=listener).start()
    drv = MavlinkDriver(cfg.robots[0], pool=LinkPool())
    out: list[float] = []
    try:
        drv.connect(timeout=5.0)
        for i in range(samples + 20):
            vx = 0.001 * (i % 200 + 1)
            got.clear()
            t0 = time.perf_counter()
            drv.send(Twist2D(t=0.0, vx=vx, ttl=10.0))
            while got.wait(1.0) and not math.isclose(stamp["vx"], vx, abs_tol=1e-6):
                got.clear()  # a keepalive re-send of the previous value
            if i >= 20:
                out.append(stamp["t"] - t0)
            drv.poll()
            time.sleep(0.002)
    finally:
        drv.close()
        emu.stop()
    return out


def raw_latency(samples: int) -> list[float]:
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    veh = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1)
    veh.mav.heartbeat_send(mc.TYPE_GROUND_ROVER, mc.AUTOPILOT_ARDUPILOT, 0, 0, 0)
    while gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0) is None:
        pass
    got = threading.Event()
    stamp: dict[str, float] = {}
    stop = threading.Event()

    def receiver() -> None:
        fd = veh.port.fileno()
        while not stop.is_set():
            select.select([fd], [], [], 0.02)
            while (m := veh.recv_msg()) is not None:
                if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                    stamp["t"] = time.perf_counter()
                    got.set()

    th = threading.Thread(target=receiver, daemon=True)
    th.start()
    out: list[float] = []
    try:
        for i in range(samples + 20):
            got.clear()
            t0 = time.perf_counter()
            gcs.mav.set_position_target_local_ned_send(
                0, 1, 1, mc.FRAME_BODY_NED, mc.MASK_VELOCITY_YAW_RATE,
                0, 0, 0, 0.1, 0, 0, 0, 0, 0, 0, 0,
            )  # fmt: skip
            got.wait(1.0)
            if i >= 20:
                out.append(stamp["t"] - t0)
            time.sleep(0.002)
    finally:
        stop.set()
        th.join()
        gcs.close()
        veh.close()
    return out


def pose_rates(n: int, seconds: float) -> dict[str, float]:
    port = free_udp_port()
    cfg = make_config(n, port)
    world = IdealWorld(cfg)
    lock = threading.Lock()
    emus = [VehicleEmulator(world, r, world_lock=lock).start() for r in cfg.robots]
    pool = LinkPool()
    drivers = [MavlinkDriver(r, pool=pool) for r in cfg.robots]
    stop = threading.Event()

    def stepper() -> None:
        t_next = time.monotonic()
        while not stop.is_set():
            with lock:
                world.step(0.01)
            t_next += 0.01
            stop.wait(max(0.0, t_next - time.monotonic()))

    th = threading.Thread(target=stepper, daemon=True)
    th.start()
    try:
        for d in drivers:
            d.connect(timeout=5.0)
        for d in drivers:
            d.poll()
        counts = [0] * n
        t0 = time.monotonic()
        while (now := time.monotonic()) - t0 < seconds:
            for i, d in enumerate(drivers):
                d.send(Twist2D(t=now, vx=0.05, wz=0.1))
                counts[i] += len(d.poll())
            time.sleep(0.01)
        elapsed = time.monotonic() - t0
        rates = [c / elapsed for c in counts]
        healthy = sum(d.health().ok for d in drivers)
    finally:
        for d in drivers:
            d.close()
        stop.set()
        th.join()
        for e in emus:
            e.stop()
    return {
        "median": round(float(np.median(rates)), 2),
        "min": round(float(np.min(rates)), 2),
        "requested": cfg.robots[0].telemetry_hz,
        "healthy": healthy,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=400)
    ap.add_argument("--seconds", type=float, default=3.0)
    args = ap.parse_args()
    raw: list[float] = []
    ada: list[float] = []
    blocks = 4  # interleaved, so machine load drifts hit both alike
    for b in range(blocks):
        print(f"latency block {b + 1}/{blocks} ...", file=sys.stderr)
        raw += raw_latency(args.samples // blocks)
        ada += adapter_latency(args.samples // blocks)
    rates = {}
    for n in (1, 10):
        print(f"pose rate with {n} robots ...", file=sys.stderr)
        rates[str(n)] = pose_rates(n, args.seconds)
    raw_s, ada_s = stats_ms(raw), stats_ms(ada)
    print(
        json.dumps(
            {
                "latency_ms": {
                    "adapter": ada_s,
                    "raw_pymavlink": raw_s,
                    "ratio": round(ada_s["median"] / raw_s["median"], 3),
                },
                "pose_rate_hz": rates,
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
