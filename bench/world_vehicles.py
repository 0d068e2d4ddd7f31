"""What MAVLink vehicles cost ``fleet world`` (``--mavlink``); prints one JSON object on stdout.

The rehearsal world of tests/integration/test_world_lab.py (ideal backend at 60 Hz, four robots
around a crate), one world-loop iteration at a time as ``controller.runtime.world._serve`` runs
it: MAVLink in, physics for 20 ms (the loop's 50 Hz), telemetry out. Baseline, in the same
process: the same four robots all ``sim`` bodies (no emulator). Measured: two of them (r1 a PX4,
r3 an ArduRover) emulated vehicles, their real drivers connected over loopback UDP and streaming
(serviced between iterations, outside the timed section, as their own processes would).

- ``loop_ms``: median and p90 of one iteration, both ways, and ``ratio`` (vehicles / baseline);
- ``pump_us``: median of one ``pump_vehicles`` call (both emulators: inbound, failsafes,
  command, telemetry due);
- ``poses_per_s``: poses each driver received per simulated second (telemetry asked at 50 Hz,
  bounded by the loop's rate).

Usage: python bench/world_vehicles.py [--iterations N]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from controller.config import parse_config  # noqa: E402
from controller.runtime.wiring import make_hub  # noqa: E402
from controller.runtime.world import (  # noqa: E402
    _start_vehicles,
    emulated_vehicles,
    pump_vehicles,
    world_config,
)
from drivers.mavlink.driver import MavlinkDriver  # noqa: E402
from drivers.mavlink.link import LinkPool  # noqa: E402
from tests.support.config import base_config_dict  # noqa: E402
from tests.support.mavlink_rig import free_udp_port  # noqa: E402

LOOP_DT = 0.02  # s: the world's loop at 50 Hz
STARTS = ([3.4, 2.2, 1.57], [4.4, 3.2, 3.14], [3.2, 4.3, -1.57], [2.1, 3.3, 0.0])
MAVLINK = {"r1": ("px4", 1), "r3": ("ardurover", 3)}


def config(with_vehicles: bool):
    data = base_config_dict()
    data["robots"] = data["robots"][:4]
    for r, start in zip(data["robots"], STARTS, strict=True):
        r["start"] = start
        if with_vehicles and r["id"] in MAVLINK:
            profile, sysid = MAVLINK[r["id"]]
            r.update(driver="mavlink", profile=profile, system_id=sysid,
                     url=f"udpin:127.0.0.1:{free_udp_port()}")  # fmt: skip
    data["object"].update(
        polygon=[[0.0, 0.0], [0.6, 0.0], [0.6, 0.4], [0.0, 0.4]],
        start=[3.0, 3.0, 0.0],
        motion={"kind": "line", "speed": 0.03, "heading": 0.0, "max_force": 4.0},
    )
    data["sim"].update(backend="ideal", timestep=1.0 / 60.0, seed=3)
    return parse_config(data)


def run(with_vehicles: bool, iterations: int) -> dict:
    cfg = config(with_vehicles)
    vehicles = emulated_vehicles(cfg, "all" if with_vehicles else None)
    hub = make_hub(world_config(cfg, vehicles))
    emus = _start_vehicles(cfg, hub, vehicles)
    pool = LinkPool()
    drivers: list[MavlinkDriver] = []

    def step(timed: list[float] | None, pumps: list[float] | None) -> None:
        t0 = time.perf_counter()
        target = hub.t + LOOP_DT
        p0 = time.perf_counter()
        pump_vehicles(emus, target)
        p1 = time.perf_counter()
        hub.advance_to(target)
        pump_vehicles(emus, hub.t)
        t1 = time.perf_counter()
        if timed is not None:
            timed.append((t1 - t0) * 1e3)
        if pumps is not None and emus:
            pumps.append((p1 - p0) * 1e6)
        for d in drivers:
            d.health()

    try:
        for r in cfg.robots:
            if r.id in vehicles:
                d = MavlinkDriver(r, clock=lambda: hub.t, idle=lambda dt: step(None, None),
                                  pool=pool)  # fmt: skip
                d.connect(timeout=3.0)
                drivers.append(d)
        for d in drivers:
            d.poll()
        t_start = hub.t
        loops: list[float] = []
        pumps: list[float] = []
        for _ in range(iterations):
            step(loops, pumps)
        sim_s = hub.t - t_start
        poses = [len(d.poll()) / sim_s for d in drivers]
    finally:
        for d in drivers:
            d.close()
        for e in emus:
            e.stop()
        hub.world.close()
    loops.sort()
    out = {
        "median": round(statistics.median(loops), 3),
        "p90": round(loops[int(0.9 * len(loops))], 3),
    }
    if pumps:
        out["pump_us"] = round(statistics.median(pumps), 1)
        out["poses_per_s"] = [round(p, 1) for p in poses]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=500)
    args = ap.parse_args()
    print("baseline: four sim bodies", file=sys.stderr)
    base = run(False, args.iterations)
    print("measured: two of them emulated MAVLink vehicles", file=sys.stderr)
    veh = run(True, args.iterations)
    out = {
        "iterations": args.iterations,
        "loop_ms": {
            "sim_only": {k: base[k] for k in ("median", "p90")},
            "with_vehicles": {k: veh[k] for k in ("median", "p90")},
            "ratio": round(veh["median"] / base["median"], 3),
        },
        "pump_us": veh["pump_us"],
        "poses_per_s": veh["poses_per_s"],
        "loadavg": [round(x, 2) for x in os.getloadavg()],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
