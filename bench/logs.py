"""Benchmark the logs: the Foxglove scene's cost, the recorder with and without it, the regression
replay, the live view's offer. Prints one JSON object.

- scene builder (pure): µs per bus message over a synthetic lockstep stream (20 Hz ticks, every
  robot's command, state and truth, the object's), for 6 and 64 robots; medians of ``--reps``;
- recorder: bus messages per second written by ``McapRecorder`` from a synthetic stream, with
  the scene channels (``log.scene_hz`` 10) and without (0), same process, alternated; bytes of
  log per sim second; ratio with/without;
- regression replay of the golden capture log (tests/replay/data/capture.mcap): seconds, and
  sim seconds replayed per wall second;
- dry run: wall time of a 6-robot ideal run with and without the scene, alternated;
- live view: µs per ``offer`` (never blocks: a full queue drops).

Usage: python bench/logs.py [--reps 3] [--seconds 10]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controller import wire  # noqa: E402
from controller.config import parse_config  # noqa: E402
from controller.io.recorder import SIM_EPOCH, McapRecorder  # noqa: E402
from controller.scene.builder import SceneBuilder  # noqa: E402

XS = [0.5 + 1.5 * i for i in range(8)]
YS = [0.5, 1.2, 1.9, 6.5, 7.2, 7.9, 8.6, 9.3]


def config(n: int, scene_hz: float = 10.0):
    import tomllib

    data = tomllib.loads((ROOT / "fleet.toml").read_text())
    data["robots"] = [
        {"id": f"r{k + 1}", "kind": "omni", "radius": 0.1, "start": [XS[k % 8], YS[k // 8], 0.0]}
        for k in range(n)
    ]
    data["log"] = {"scene_hz": scene_hz}
    return parse_config(data, "bench")


def stream(cfg, seconds: float) -> list[tuple[str, bytes]]:
    """A lockstep run's bus traffic: per 20 Hz tick, truth, commands, states, the object."""
    f = cfg.fleet.name
    out = []
    for k in range(int(seconds * 20)):
        t = 0.05 * k
        msgs = [
            (wire.key("truth_object", f), wire.PoseMeasurement(t=t, x=2 + 0.01 * t, y=3, theta=0))
        ]
        for r in cfg.robots:
            x, y = r.start[0] + 0.05 * t, r.start[1]
            msgs.append(
                (wire.key("truth_robot", f, id=r.id), wire.PoseMeasurement(t=t, x=x, y=y, theta=0))
            )
            msgs.append((wire.key("robot_cmd", f, id=r.id), wire.Twist2D(t=t, vx=0.05)))
            msgs.append(
                (
                    wire.key("robot_state", f, id=r.id),
                    wire.RobotState(t=t, id=r.id, x=x, y=y, theta=0, vx=0.05),
                )
            )
        msgs.append(
            (wire.key("object_state", f), wire.ObjectState(t=t, x=2 + 0.01 * t, y=3, theta=0))
        )
        out += [(key, wire.encode(m)) for key, m in msgs]
    return out


def bench_builder(n: int, seconds: float, reps: int) -> dict:
    cfg = config(n)
    msgs = [(k, json.loads(p)) for k, p in stream(cfg, seconds)]
    times = []
    for _ in range(reps):
        b = SceneBuilder(cfg, time_offset=SIM_EPOCH)
        t0 = time.perf_counter()
        made = 0
        for k, obj in msgs:
            made += len(b.ingest(k, obj))
        made += len(b.flush())
        times.append(time.perf_counter() - t0)
    med = float(np.median(times))
    return {
        "robots": n,
        "bus_messages": len(msgs),
        "scene_messages": made,
        "us_per_bus_message": round(med / len(msgs) * 1e6, 2),
        "ms_per_sim_second": round(med / seconds * 1e3, 2),
    }


def record(cfg, msgs, path: Path) -> tuple[float, int]:
    scene = SceneBuilder(cfg, time_offset=SIM_EPOCH) if cfg.log.scene_hz > 0 else None
    t0 = time.perf_counter()
    rec = McapRecorder(path, cfg.fleet.name, 0.5, sim_epoch=SIM_EPOCH, scene=scene)
    for k, p in msgs:
        rec.on_sample(k, p, 0.0)
    rec.close()
    return time.perf_counter() - t0, path.stat().st_size


def bench_recorder(n: int, seconds: float, reps: int) -> dict:
    with_scene, without = config(n, 10.0), config(n, 0.0)
    msgs = stream(with_scene, seconds)
    res: dict[str, list] = {"with": [], "without": [], "bytes_with": [], "bytes_without": []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(reps):
            for name, cfg in (("with", with_scene), ("without", without)):
                dt, size = record(cfg, msgs, Path(tmp) / f"{name}{r}.mcap")
                res[name].append(dt)
                res[f"bytes_{name}"].append(size)
    w, wo = float(np.median(res["with"])), float(np.median(res["without"]))
    return {
        "robots": n,
        "bus_messages": len(msgs),
        "msgs_per_s_with_scene": round(len(msgs) / w),
        "msgs_per_s_without": round(len(msgs) / wo),
        "time_ratio_with_over_without": round(w / wo, 3),
        "kb_per_sim_second_with_scene": round(np.median(res["bytes_with"]) / seconds / 1024, 1),
        "kb_per_sim_second_without": round(np.median(res["bytes_without"]) / seconds / 1024, 1),
    }


def bench_dry_run(reps: int, seconds: float = 5.0) -> dict:
    """Wall time of a 6-robot ideal dry run (robots driving to points) with and without the
    scene channels, alternated in the same process: what the scene costs the run itself."""
    from controller.mission.basic import GotoMission
    from controller.mission.tracking import RobotLimits
    from controller.runtime.dry_run import DryRun
    from controller.runtime.sweep import on_free_port

    walls: dict[float, list[float]] = {0.0: [], 10.0: []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(reps):
            for hz in walls:
                import tomllib

                data = tomllib.loads((ROOT / "fleet.toml").read_text())
                data["sim"]["backend"] = "ideal"
                data["log"] = {"scene_hz": hz}
                cfg = on_free_port(parse_config(data, "bench"))
                goals = np.array([[r_.start[0] + 1.0, r_.start[1] + 1.0] for r_ in cfg.robots])
                mission = GotoMission(goals, RobotLimits.from_config(cfg.robots))
                res = DryRun(cfg, mission, Path(tmp) / f"{hz}-{r}.mcap", max_time=seconds).run()
                walls[hz].append(res["wall_time_s"])
    w, wo = float(np.median(walls[10.0])), float(np.median(walls[0.0]))
    return {"robots": 6, "sim_s": seconds, "wall_s_with_scene": round(w, 3),
            "wall_s_without": round(wo, 3), "ratio": round(w / wo, 3)}  # fmt: skip


def bench_check() -> dict:
    from controller.replay.check import check_log

    golden = ROOT / "tests" / "replay" / "data" / "capture.mcap"
    t0 = time.perf_counter()
    r = check_log(golden)
    dt = time.perf_counter() - t0
    sim = r["ticks"] * 0.05
    return {"log": golden.name, "ok": r["ok"], "ticks": r["ticks"], "seconds": round(dt, 2),
            "sim_s_per_wall_s": round(sim / dt, 2)}  # fmt: skip


def bench_offer(n: int = 20000) -> dict:
    from controller.io.liveview import LiveView

    view = LiveView(port=0, queue_size=4096)
    payload = b'{"t":1.0}'
    t0 = time.perf_counter()
    for _ in range(n):
        view.offer("/x", "", b"", payload, 0)
    dt = time.perf_counter() - t0
    view.close()
    return {"offers": n, "us_per_offer": round(dt / n * 1e6, 2), "dropped": view.dropped}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    out = {
        "load_avg_1min": round(os.getloadavg()[0], 2),
        "builder": [bench_builder(n, args.seconds, args.reps) for n in (6, 64)],
        "recorder": [bench_recorder(n, args.seconds, args.reps) for n in (6, 64)],
        "dry_run": bench_dry_run(args.reps),
        "check": bench_check(),
        "live_view": bench_offer(),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
