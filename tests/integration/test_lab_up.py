"""The lab in one command (``fleet up``), the lab way: hub, stand-in world, six agents and the
daemon, each a process of its own, on 127.0.0.1.

- The README's lab block, as written, in a fresh folder: the shipped rehearsal config brought
  up detached, its operator's resume held back 60 s (a slow bring-up), the crate delivered,
  judged from the world's truth in the daemon's MCAP; the crate did not move before the
  resume; no robot stopped by its watchdog while the daemon drove it; late ticks rare.
- Ctrl-C in the foreground with a CPU hog on every core: a crashed agent restarted under an
  engaged e-stop comes up stopped; the SIGINT engages the e-stop first, the console's output
  ends with the verdict, the MCAP is readable, and from a second after the e-stop every
  command to the world was zero and no robot moved more than 2 cm.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from controller.replay.log import load_run
from controller.runtime.lab import pid_alive, read_state
from tests.support.config import ROOT, free_port, write_toml
from tests.support.hog import cpu_hogs
from tests.support.lab import connect_client, fleet, latch_states, stop_all
from tests.support.wait import wait_for

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

RESUME_DELAY = 60.0  # s the operator's resume comes after the lab is up (a slow bring-up)
STOP_WITHIN = 1.0  # s from the e-stop to every robot stopped, with a hog on every core
BLOCK_MARK = "<!-- lab-quickstart"


def readme_block() -> list[str]:
    """The command lines of the README's lab quick start (the fenced block after its mark)."""
    text = (ROOT / "README.md").read_text()
    after = text[text.index(BLOCK_MARK) :]
    body = after.split("```", 2)[1]
    lines = [ln.split("#", 1)[0].strip() for ln in body.splitlines()[1:]]
    return [ln for ln in lines if ln]


def _env() -> dict[str, str]:
    """``fleet`` on the PATH as the README's reader has it (the venv's bin)."""
    bindir = str(Path(sys.executable).parent)
    return dict(os.environ, PATH=f"{bindir}{os.pathsep}{os.environ['PATH']}", PYTHONPATH=str(ROOT))


def _port_free(port: int) -> bool:
    """Nothing listens on ``port`` (a connection of an earlier run in TIME_WAIT is no obstacle:
    zenoh binds with SO_REUSEADDR, as this does)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _path_after(tracks: dict[str, list], t0: float) -> dict[str, tuple[float, float]]:
    """Each track's path length (m) from ``t0`` to its end, and how long that is (s) (rows t,
    x, y, theta)."""
    out = {}
    for rid, rows in tracks.items():
        a = np.array([r for r in rows if r[0] >= t0])
        if len(a) < 2:
            out[rid] = (0.0, 0.0)
            continue
        out[rid] = (float(np.hypot(np.diff(a[:, 1]), np.diff(a[:, 2])).sum()), a[-1, 0] - a[0, 0])
    return out


@pytest.mark.timeout(900)  # the whole block: bring-up, a minute's delay, the job, the log read
def test_the_readme_lab_block_delivers_the_crate_with_the_resume_a_minute_late(tmp_path):
    lines = readme_block()
    assert [ln.split()[1] for ln in lines] == ["init", "up", "status", "resume", "down"], lines
    assert _port_free(7447), "the shipped lab.toml listens on 127.0.0.1:7447: something is there"
    outputs = {}
    try:
        for line in lines:
            word = line.split()[1]
            if word == "resume":  # the lab was up (and fleet status answered): a minute goes by
                time.sleep(RESUME_DELAY)  # the scenario: an operator a minute late, not a wait
            proc = subprocess.run(
                line, shell=True, cwd=tmp_path, env=_env(), capture_output=True, text=True,
                timeout=900,
            )  # fmt: skip
            outputs[word] = proc
            assert proc.returncode == 0, (line, proc.stdout[-3000:], proc.stderr[-3000:])
    finally:
        state = read_state(tmp_path / "runs" / "lab-lab.json") or {}
        if state.get("stage") not in (None, "ended"):  # never leave a lab behind
            subprocess.run(
                "fleet down --config lab.toml", shell=True, cwd=tmp_path, env=_env(), timeout=300
            )
    status = outputs["status"].stdout
    assert status.count(": present") == 6, status
    assert "e-stop UNKNOWN (stopped)" in status  # a fresh lab: fail closed until the resume
    down = outputs["down"].stdout
    assert down.startswith("DELIVERED"), down
    run_dir = Path(state["run_dir"])
    run = load_run(run_dir / "daemon.mcap")
    # the crate held its start pose until the operator's resume, a minute after bring-up
    releases = [e["t"] for e in run.estops if not e["engaged"]]
    assert releases, run.estops
    obj = np.array(run.object_truth)
    before = obj[obj[:, 0] < releases[0]]
    assert before[-1, 0] - before[0, 0] > RESUME_DELAY - 5.0  # the world ran all that while
    assert np.abs(before[:, 1:3] - before[0, 1:3]).max() < 0.01, "the crate moved before resume"
    # the job ran in real time: late ticks rare, no watchdog stop while the daemon drove
    daemon_log = (run_dir / "daemon.log").read_text()
    done = re.search(r"^(\S+ \S+) INFO .*mission done in phase done", daemon_log, re.M)
    assert done, daemon_log[-3000:]
    health = re.search(r"(\d+) ticks, (\d+) late", daemon_log)
    ticks, late = (int(g) for g in health.groups())
    # late ticks (over the 50 ms period): 0-1 of ~2 300 on the machine the lab way was first
    # measured on; 125 of 4 494 (2.8 %) on this CI machine (an AMD EPYC whose dry runs are
    # 2.5x slower), idle: the tick is near its period there (issue 33). Bounded at 5 %.
    assert late <= max(5, ticks // 20), (late, ticks)
    for rid in [f"r{i}" for i in range(1, 7)]:
        stops = [
            ln
            for ln in (run_dir / f"{rid}.log").read_text().splitlines()
            if "watchdog stop" in ln and ln[:23] < done.group(1)
        ]
        assert not stops, (rid, stops[:3])
    print(
        f"\nlab block: up in {state.get('ready_s')} s; {ticks} ticks, {late} late; {down}",
        file=sys.stderr,
    )


def lab_config(tmp_path: Path, port: int) -> Path:
    data = tomllib.loads((ROOT / "lab.toml").read_text())
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "lab.toml", data)


def test_ctrl_c_stops_every_robot_first_and_leaves_a_readable_log_under_load(tmp_path):
    port = free_port()
    cfg = lab_config(tmp_path, port)
    state_file = tmp_path / "runs" / "lab-lab.json"
    console = tmp_path / "console.txt"
    with cpu_hogs(), open(console, "w") as out:
        up = subprocess.Popen(
            [sys.executable, "-m", "controller.cli", "up", "--config", str(cfg), "--plain"],
            cwd=ROOT, env=_env(), stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip
        try:
            wait_for(lambda: (read_state(state_file) or {}).get("stage") == "waiting", 300, "up")
            state = read_state(state_file)
            assert fleet("resume", "--config", str(cfg), "--timeout", "20").returncode == 0
            bus = connect_client(port, "the hub")
            try:
                wait_for(lambda: _phase(cfg) in ("close_in", "hold", "arrested"), 120, "moving")
                # an engaged e-stop, then an agent crashes: its restart comes up stopped
                assert fleet("estop", "--config", str(cfg), "--timeout", "20").returncode == 0
                os.kill(state["parts"]["r1"]["pid"], signal.SIGKILL)
                wait_for(lambda: _restarted(state_file, "r1"), 120, "r1 restarted and ready")
                wait_for(lambda: "robot/r1" in latch_states(bus), 30, "r1's latch")
                assert latch_states(bus)["robot/r1"].engaged  # never lifted by the restart
                assert fleet("resume", "--config", str(cfg), "--timeout", "20").returncode == 0
                wait_for(lambda: not latch_states(bus)["robot/r1"].engaged, 30, "r1 resumed")
                truth = bus.subscribe_topic("truth_robot", lossless=True)  # the world's, to its end
                cmds = bus.subscribe_topic("world_cmd", lossless=True)  # agents' to the world
                up.send_signal(signal.SIGINT)  # the operator's Ctrl-C
                code = up.wait(timeout=180)
                rows = [(item.key, item.msg) for item in truth.drain()]
                cmd_rows = [(item.key, item.msg) for item in cmds.drain()]
            finally:
                bus.close()
        finally:
            stop_all([up])
    text = console.read_text()
    assert code == 1, text[-3000:]  # stopped, not done
    tail = text.strip().splitlines()
    verdict = next(ln for ln in tail if ln.startswith(("STOPPED", "DELIVERED", "FAILED")))
    assert verdict.startswith("STOPPED"), text[-3000:]
    assert tail.index(verdict) > max(i for i, ln in enumerate(tail) if ln.startswith("["))
    assert "NOT confirmed" not in text  # the e-stop at the end reached every agent
    final = read_state(state_file)
    assert final["stage"] == "ended" and final["exit"] == 1
    run = load_run(Path(final["run_dir"]) / "daemon.mcap")  # whole: it reads
    assert run.complete
    last_engage = max(e["t"] for e in run.estops if e["engaged"])
    assert last_engage > max(e["t"] for e in run.estops if not e["engaged"])
    # from STOP_WITHIN after the e-stop until the world was stopped, last but the hub: every
    # command an agent gave the world was zero, and no robot moved more than 2 cm (a robot
    # still driven would cover 0.4 m a second; the live crate pushing on a stopped cage can
    # make a robot creep a few mm, a single 50 ms sample above 2 cm/s)
    late = [(k, m) for k, m in cmd_rows if m.t > last_engage + STOP_WITHIN]
    assert all(m.vx == m.vy == m.wz == 0.0 for _, m in late), [x for x in late if x[1].vx][:3]
    tracks: dict[str, list] = {}
    for key, m in rows:
        tracks.setdefault(key, []).append((m.t, m.x, m.y, m.theta))
    moved = _path_after(tracks, last_engage + STOP_WITHIN)
    assert len(moved) == 6, moved
    assert all(span > 0.3 and path < 0.02 for path, span in moved.values()), moved
    daemon = (Path(final["run_dir"]) / "daemon.log").read_text()
    stopped = re.search(r"fleet daemon: stopped.*", daemon)
    print(
        f"\nlab under load: up in {final.get('ready_s')} s; restarts {final['outcome']['restarts']}"
        f"; robots moved at most {1000 * max(p for p, _ in moved.values()):.1f} mm from "
        f"{STOP_WITHIN} s after the e-stop"
        f"; {stopped.group(0) if stopped else 'no stop line'}",
        file=sys.stderr,
    )


def _phase(cfg: Path) -> str:
    proc = fleet("status", "--config", str(cfg), "--json", "--timeout", "2")
    try:
        return json.loads(proc.stdout).get("phase", "")
    except json.JSONDecodeError:
        return ""


def _restarted(state_file: Path, rid: str) -> bool:
    part = ((read_state(state_file) or {}).get("parts") or {}).get(rid) or {}
    return part.get("restarts", 0) >= 1 and bool(part.get("ready"))


def test_agents_in_groups_come_up_and_fleet_down_stops_a_lab_before_its_resume(tmp_path):
    """Three agents to a process (a thread each), the ideal world, detached; ``fleet down``
    before any resume: the lab stops with a verdict saying so, exit 1, nothing left running."""
    port = free_port()
    data = tomllib.loads((ROOT / "lab.toml").read_text())
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["log"] = {"dir": str(tmp_path / "runs")}
    data["sim"]["backend"] = "ideal"
    cfg = write_toml(tmp_path / "lab.toml", data)
    c = str(cfg)
    up = fleet("up", "--config", c, "--detach", "--agents-per-process", "3", timeout=300)
    assert up.returncode == 0, up.stdout + up.stderr
    assert "fleet resume --config" in up.stdout  # the next step, named
    state = read_state(tmp_path / "runs" / "lab-lab.json")
    agents = [k for k in state["parts"] if k.startswith("r")]
    assert agents == ["r1,r2,r3", "r4,r5,r6"] and all(state["parts"][k]["ready"] for k in agents)
    status = fleet("status", "--config", c, "--json")
    robots = json.loads(status.stdout)["robots"]
    assert [r["present"] for r in robots] == [True] * 6
    down = fleet("down", "--config", c, "--json", timeout=300)
    result = json.loads(down.stdout)
    assert down.returncode == 1 and result["status"] == "stopped", result
    assert "before any resume" in result["verdict"]
    assert "every robot e-stopped" in result["verdict"]
    final = read_state(tmp_path / "runs" / "lab-lab.json")
    pids = [p["pid"] for p in final["parts"].values()] + [final["pid"]]
    assert not [p for p in pids if p and pid_alive(p)]  # (a zombie awaiting its reaper: gone)
