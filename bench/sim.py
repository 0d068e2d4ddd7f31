"""Benchmark the stand-in worlds: robots + a live object at 240 Hz.

Prints one JSON object on stdout:
``{"real_time_factor": {"4": x, "16": y, "50": z}, "steps_per_s": {...}, "ideal": {...}, ...}``
(medians over repeats; the ideal backend, same scenario and process, is the baseline for ratios).
Progress goes to stderr. Usage: ``python bench/sim.py [--repeats N] [--seconds S]``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

from controller.config import FleetConfig, parse_config
from sim_backend.factory import make_world

COUNTS = (4, 16, 50)


def scenario(n: int, backend: str) -> FleetConfig:
    """n robots (alternately omni and diff) in rows along the south wall, an L-shaped object
    drifting on a sine path in the middle of the room."""
    robots = [
        {
            "id": f"r{i}",
            "kind": "omni" if i % 2 == 0 else "diff",
            "start": [0.6 + 0.6 * (i % 20), 0.6 + 0.6 * (i // 20), 0.0],
            "max_force": 6.0,
        }
        for i in range(n)
    ]
    return parse_config(
        {
            "fleet": {"name": "bench"},
            "object": {
                "polygon": [[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]],
                "start": [3.0, 7.0, 0.0],
                "goal": [9.0, 9.0, 0.0],
                "motion": {"kind": "sine", "speed": 0.1, "amplitude": 0.4, "max_force": 4.0},
            },
            "robots": robots,
            "sim": {"backend": backend, "timestep": 1.0 / 240.0},
        }
    )


def run(n: int, backend: str, seconds: float, repeats: int) -> dict[str, float]:
    """Median physics steps per second over ``repeats`` chunks of ``seconds`` of sim time, by
    wall clock and by this process's CPU time (the machine is shared: CPU time is steadier)."""
    cfg = scenario(n, backend)
    world = make_world(cfg)
    try:
        wall, cpu = [], []
        tick = 1.0 / 20.0  # commands change at the controller's 20 Hz, as in the dry run
        steps_per_chunk = int(round(seconds / cfg.sim.timestep))
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            for _ in range(int(round(seconds / tick))):
                k = world.t
                for i, rid in enumerate(world.robot_ids):
                    world.set_command(rid, 0.15, 0.05, 0.4 * math.sin(0.5 * k + i))
                world.step(tick)
            wall.append(steps_per_chunk / (time.perf_counter() - t0))
            cpu.append(steps_per_chunk / max(time.process_time() - c0, 1e-9))
        return {"wall": statistics.median(wall), "cpu": statistics.median(cpu)}
    finally:
        world.close()


def physics_only(n: int, seconds: float, repeats: int) -> float:
    """Median wall-clock steps/s of bare ``stepSimulation`` on the same pybullet world (the
    floor our per-step Python work adds to)."""
    import pybullet as pb

    world = make_world(scenario(n, "pybullet"))
    try:
        steps = int(round(seconds * 240))
        rates = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(steps):
                pb.stepSimulation(physicsClientId=world._cid)
            rates.append(steps / (time.perf_counter() - t0))
        return statistics.median(rates)
    finally:
        world.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=1.0, help="sim seconds per repeat")
    args = ap.parse_args(argv)
    hz = 240.0
    out: dict = {
        "real_time_factor": {},
        "steps_per_s": {},
        "cpu_real_time_factor": {},
        "physics_only_steps_per_s": {},
        "ideal": {},
        "ratio_to_ideal": {},
    }
    for n in COUNTS:
        key = str(n)
        print(f"pybullet, {n} robots ...", file=sys.stderr)
        sps = run(n, "pybullet", args.seconds, args.repeats)
        print(f"bare stepSimulation, {n} robots ...", file=sys.stderr)
        bare = physics_only(n, args.seconds, args.repeats)
        print(f"ideal, {n} robots ...", file=sys.stderr)
        ideal = run(n, "ideal", args.seconds, args.repeats)
        out["steps_per_s"][key] = round(sps["wall"], 1)
        out["real_time_factor"][key] = round(sps["wall"] / hz, 2)
        out["cpu_real_time_factor"][key] = round(sps["cpu"] / hz, 2)
        out["physics_only_steps_per_s"][key] = round(bare, 1)
        out["ideal"][key] = {
            "steps_per_s": round(ideal["wall"], 1),
            "real_time_factor": round(ideal["wall"] / hz, 2),
        }
        out["ratio_to_ideal"][key] = round(sps["wall"] / ideal["wall"], 3)
    out["timestep_hz"] = hz
    out["goal_rtf_16_met"] = out["real_time_factor"]["16"] >= 5.0
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
