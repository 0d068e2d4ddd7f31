"""Benchmark ``fleet up``: the lab's bring-up and what its parts cost, agents as a process each
or several to a process. Prints one JSON object.

For each size (``--sizes``, default 6 and 20 robots: fleet.toml's job with its robots in rows
along the south wall, every robot ``sim`` in the shared world, pybullet as the rehearsal runs)
and each ``--per-process`` (default 1 and the whole fleet), the lab is brought up exactly as
``fleet up`` does (``controller.runtime.lab.Lab``: hub, world, agents, daemon, each gated on
the bus), an operator's resume is put, and for ``--seconds`` the daemon holds every robot still
(``--mission hold``: 20 Hz commands, 30 Hz poses, the e-stop released). Measured:

- ``ready_s``: bring-up, from the first process started to every part ready;
- CPU (% of one core, from /proc utime+stime over the window, each part with its live
  children: the daemon's planner worker) and memory (RSS, MB) of the agents, the world, the
  daemon and the hub, summed per role;
- the daemon's tick p50/p99 (ms, ``fleet status``) and its late ticks over the window.

``--hog`` runs the same beside a CPU hog on every core. The machine's load average is reported.

Usage: python bench/lab.py [--sizes 6,20] [--per-process 1,0] [--seconds 20] [--hog]
(``--per-process 0``: every agent in one process)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controller.config import load_config  # noqa: E402
from controller.runtime.lab import Lab, plan_parts  # noqa: E402
from tests.support.config import free_port, write_toml  # noqa: E402
from tests.support.hog import cpu_hogs  # noqa: E402

TICK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def config(n: int, port: int, workdir: Path) -> Path:
    """fleet.toml's job, ``n`` sim robots in rows along the south wall, the shared world."""
    data = tomllib.loads((ROOT / "fleet.toml").read_text())
    proto = dict(data["robots"][0], kind="omni", driver="sim")
    per_row = 25
    data["robots"] = []
    for i in range(n):
        row, col = divmod(i, per_row)
        data["robots"].append(
            dict(proto, id=f"r{i + 1}", start=[0.6 + 0.46 * col, 0.6 + 0.6 * row, 0])
        )
    data["sim"]["world"] = "process"
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["log"] = {"dir": str(workdir / "runs")}
    return write_toml(workdir / f"lab-{n}.toml", data)


def _tree(pid: int) -> list[int]:
    """``pid`` and its live descendants."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            kids = Path(f"/proc/{p}/task/{p}/children").read_text().split()
        except OSError:
            kids = []
        todo += [int(k) for k in kids]
    return out


def _usage(pid: int) -> tuple[float, float]:
    """(CPU seconds so far, RSS bytes) of ``pid`` and its live children."""
    cpu = rss = 0.0
    for p in _tree(pid):
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        cpu += (int(fields[11]) + int(fields[12])) / TICK
        rss += int(fields[21]) * PAGE
    return cpu, rss


def measure(n: int, per: int, seconds: float, workdir: Path) -> dict:
    path = config(n, free_port(), workdir)
    cfg = load_config(str(path))
    run_dir = workdir / f"run-{n}-{per}"
    run_dir.mkdir(parents=True, exist_ok=True)
    parts = plan_parts(
        cfg, str(path), run_dir, "hold", agents_per_process=per or n, connect_timeout=300
    )
    stop = threading.Event()
    lab = Lab(cfg, parts, run_dir, stop, lambda snap: None, ready_timeout=300)
    result: dict = {"robots": n, "agents_per_process": per or n, "processes": len(parts)}
    try:
        if not lab.bring_up():
            result["error"] = lab.failure
            return result
        result["ready_s"] = round(lab.ready_s, 2)
        put = lab.watch.put("resume", "bench", timeout=30)
        result["resume_confirmed"] = bool(put and not put["agents_missing"])
        time.sleep(2.0)  # the bench's settling time before the window, not a handshake
        result.update(_window(lab, parts, n, seconds))
    finally:
        lab.shut_down()
    return result


def _window(lab: Lab, parts, n: int, seconds: float) -> dict:
    """CPU, memory and ticks over ``seconds`` of the running lab."""
    before = {p.name: _usage(p.proc.pid) for p in parts}
    st0 = lab.watch.status()
    t0 = time.monotonic()
    time.sleep(seconds)  # the measurement window
    wall = time.monotonic() - t0
    after = {p.name: _usage(p.proc.pid) for p in parts}
    st1 = lab.watch.status()
    by_role: dict[str, dict] = {}
    for p in parts:
        role = by_role.setdefault(p.role, {"cpu_pct": 0.0, "rss_mb": 0.0, "n": 0})
        role["cpu_pct"] += 100 * (after[p.name][0] - before[p.name][0]) / wall
        role["rss_mb"] += after[p.name][1] / 1e6
        role["n"] += 1
    out: dict = {
        "by_role": {
            k: {"cpu_pct": round(v["cpu_pct"], 1), "rss_mb": round(v["rss_mb"], 1), "n": v["n"]}
            for k, v in by_role.items()
        },
        "agents_cpu_pct_per_robot": round(by_role["agent"]["cpu_pct"] / n, 2),
        "agents_rss_mb_per_robot": round(by_role["agent"]["rss_mb"] / n, 1),
    }
    if st0 is not None and st1 is not None:
        out["tick_ms"] = {k: round(v, 1) for k, v in st1.tick_ms.items()}
        for k in ("ticks", "late_ticks"):
            out[k] = st1.counters.get(k, 0) - st0.counters.get(k, 0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="6,20")
    ap.add_argument("--per-process", default="1,0")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--hog", action="store_true")
    args = ap.parse_args()
    import tempfile

    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (int(s) for s in args.sizes.split(",")):
            for per in (int(s) for s in args.per_process.split(",")):
                print(f"lab bench: {n} robots, {per or n} agents per process", file=sys.stderr)
                if args.hog:
                    with cpu_hogs():
                        runs.append(measure(n, per, args.seconds, Path(tmp)))
                else:
                    runs.append(measure(n, per, args.seconds, Path(tmp)))
                print(json.dumps(runs[-1]), file=sys.stderr)
    print(
        json.dumps(
            {
                "bench": "lab",
                "seconds": args.seconds,
                "hog": args.hog,
                "load_avg": os.getloadavg(),
                "runs": runs,
            }
        )
    )


if __name__ == "__main__":
    sys.exit(main())
