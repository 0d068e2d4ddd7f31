"""The whole job with a large fleet (issue 33 item 2): the dry run and the lab in real time.

Prints ONE JSON object on stdout (progress on stderr). For each ``--robots`` N: ``fleet.toml``'s
job (the L-shaped crate drifting on its sine path, its goal across the room, the three
obstacles) with N robots in three staggered rows along the south wall (every third one
differential, facing north; the others omni), then, each as a user runs it:

- ``dry_run``: ``fleet run --config X --json`` (pybullet, lockstep): status, sim and wall
  time, the transport's figures, missed ticks;
- ``lab``: ``fleet up --config X --detach`` (hub, the shared ``fleet world``, the agents grouped
  in processes as ``fleet up`` does for a large fleet, the daemon), ``fleet resume``, then
  ``fleet down --wait``: its verdict and exit, the wall time from the resume to the verdict,
  the daemon's ticks and late ticks (its log's last line) and the agents' watchdog stops while
  the daemon drove them.

The capture takes the robots the GA's set needs (six here) and the transport those holding the
crate; the other robots hold their ground (they are in the safety filter and the estimator
every tick: the scale this measures). A run that does not deliver makes the exit status 1.
``--shipped``: the repository's ``lab.toml`` as it is (the README's rehearsal: fleet.toml's six
robots where it puts them) instead of the rows, on free loopback ports; ``--robots`` is then
ignored. A row of many ``--shipped`` lab runs says how often the README's lab block delivers.

Usage: python bench/job.py [--robots 50] [--lab-repeats 2] [--no-lab] [--no-dry-run] [--keep DIR]
[--shipped] [--resume-delay S]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.support.config import free_port, write_toml  # noqa: E402

PER_ROW = 17


def write_config(n: int, workdir: Path, port: int) -> Path:
    """fleet.toml's job with ``n`` robots in rows along the south wall, for the lab too."""
    data = tomllib.loads((ROOT / "fleet.toml").read_text())
    proto = dict(data["robots"][0], driver="sim")
    data["robots"] = []
    for i in range(n):
        row, col = divmod(i, PER_ROW)
        diff = i % 3 == 2
        x = 0.5 + 0.7 * col + (0.35 if row % 2 else 0.0)
        data["robots"].append(
            dict(proto, id=f"r{i + 1}", kind="diff" if diff else "omni",
                 start=[round(x, 2), 0.5 + 0.6 * row, 1.5708 if diff else 0.0])
        )  # fmt: skip
    data["sim"]["world"] = "process"
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["log"] = {"dir": str(workdir / "runs")}
    return write_toml(workdir / f"job-{n}.toml", data)


def shipped_config(workdir: Path) -> Path:
    """The repository's lab.toml as it ships, on free loopback ports (the bus and the e-stop's
    second path), its logs in ``workdir``."""
    data = tomllib.loads((ROOT / "lab.toml").read_text())
    data["zenoh"]["listen"] = [f"tcp/127.0.0.1:{free_port()}"]
    data["zenoh"]["estop_listen"] = [f"tcp/127.0.0.1:{free_port()}"]
    data["log"] = {"dir": str(workdir / "runs")}
    return write_toml(workdir / "lab.toml", data)


def _fleet(*args: str, timeout: float = 1800) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "controller.cli", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def dry_run(cfg: Path, workdir: Path) -> dict:
    t0 = time.perf_counter()
    proc = _fleet("run", "--config", str(cfg), "--json", "--out", str(workdir / "dry.mcap"))
    wall = time.perf_counter() - t0
    try:
        out = json.loads(proc.stdout)
    except json.JSONDecodeError:
        return {"exit": proc.returncode, "error": proc.stderr[-2000:]}
    keys = ("status", "reason", "sim_time_s", "transported", "goal_error_m", "goal_error_deg",
            "transport_time_s", "arrest_time_s", "missed_ticks", "watchdog_stops",
            "min_clearance_m")  # fmt: skip
    return {"exit": proc.returncode, "wall_s": round(wall, 1), **{k: out.get(k) for k in keys}}


def lab(cfg: Path, workdir: Path, name: str, resume_delay: float = 0.0) -> dict:
    c = str(cfg)
    t0 = time.perf_counter()
    up = _fleet("up", "--config", c, "--detach", timeout=900)
    ready = time.perf_counter() - t0
    state_file = workdir / "runs" / f"lab-{name}.json"
    try:
        if up.returncode != 0:
            return {"up_exit": up.returncode, "error": (up.stdout + up.stderr)[-2000:]}
        time.sleep(resume_delay)  # an operator late (the README block's test: a minute)
        resume = _fleet("resume", "--config", c, "--timeout", "60")
        t1 = time.perf_counter()
        down = _fleet("down", "--config", c, "--wait", "--json", "--timeout", "1500")
        job_wall = time.perf_counter() - t1
    finally:
        state = json.loads(state_file.read_text()) if state_file.is_file() else {}
        if state.get("stage") not in (None, "ended"):
            _fleet("down", "--config", c, timeout=300)  # never leave a lab behind
    try:
        outcome = json.loads(down.stdout)
    except json.JSONDecodeError:
        outcome = {"error": down.stdout[-2000:] + down.stderr[-2000:]}
    brief = ("status", "verdict", "reason", "ready_s", "restarts")
    out = {"up_s": round(ready, 1), "resume_exit": resume.returncode, "exit": down.returncode,
           "job_wall_s": round(job_wall, 1),
           "outcome": {k: outcome.get(k) for k in brief if k in outcome}}  # fmt: skip
    phases = (outcome.get("job") or {}).get("phases")
    if phases:
        out["phases"] = phases
    run_dir = Path(state.get("run_dir", ""))
    log = run_dir / "daemon.log"
    if log.is_file():
        text = log.read_text(errors="replace")
        m = re.search(r"(\d+) ticks, (\d+) late, (\d+) over the .*?\(p50 ([\d.]+) ms, p99 ([\d.]+)"
                      r" ms\)", text)  # fmt: skip
        if m:
            out.update(ticks=int(m[1]), late_ticks=int(m[2]), over_budget=int(m[3]),
                       tick_p50_ms=float(m[4]), tick_p99_ms=float(m[5]))  # fmt: skip
        out["gate_episodes"] = text.count("in a row rejected by the gate")
        out["run_dir"] = str(run_dir)
        # the mission's end (done, or failed: the daemon then stops and every watchdog fires)
        done = re.search(r"^(\S+ \S+) \w+ .*mission (?:done|failed) in phase", text, re.M)
        stops = 0
        for agent_log in run_dir.glob("r*.log"):
            for line in agent_log.read_text(errors="replace").splitlines():
                if "watchdog stop" in line and (done is None or line[:23] < done[1]):
                    stops += 1
        out["watchdog_stops_while_driven"] = stops
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="50", help="fleet sizes, comma-separated")
    ap.add_argument("--no-lab", action="store_true")
    ap.add_argument("--no-dry-run", action="store_true")
    ap.add_argument("--lab-repeats", type=int, default=2, help="lab runs per size")
    ap.add_argument("--keep", default=None, help="keep the configs and runs in this folder")
    ap.add_argument("--shipped", action="store_true", help="the repository's lab.toml as is")
    ap.add_argument("--resume-delay", type=float, default=0.0, help="s from up to the resume")
    ns = ap.parse_args()
    load0 = os.getloadavg()[0]
    runs, failed = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        if ns.keep:
            tmp = str(Path(ns.keep).resolve())
        sizes = [6] if ns.shipped else [int(s) for s in ns.robots.split(",")]
        for n in sizes:
            work = Path(tmp) / f"n{n}"
            work.mkdir(parents=True, exist_ok=True)
            cfg = shipped_config(work) if ns.shipped else write_config(n, work, free_port())
            name = tomllib.loads(cfg.read_text())["fleet"]["name"]
            row: dict = {"robots": n}
            if not ns.no_dry_run:
                print(f"job: {n} robots, the dry run", file=sys.stderr)
                row["dry_run"] = dry_run(cfg, work)
                failed += row["dry_run"].get("status") != "ok"
                print(f"job: {json.dumps(row['dry_run'])}", file=sys.stderr)
            for k in range(0 if ns.no_lab else ns.lab_repeats):
                print(f"job: {n} robots, the lab in real time ({k + 1})", file=sys.stderr)
                one = lab(cfg, work, name, ns.resume_delay)
                row.setdefault("labs", []).append(one)
                verdict = (one.get("outcome") or {}).get("verdict") or ""
                failed += one.get("exit") != 0 or not verdict.startswith("DELIVERED")
                print(f"job: {json.dumps(one)}", file=sys.stderr)
            runs.append(row)
    out = {"bench": "job", "shipped": ns.shipped, "resume_delay_s": ns.resume_delay, "runs": runs,
           "load_avg_1m": [load0, os.getloadavg()[0]]}  # fmt: skip
    print(json.dumps(out, indent=1))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
