"""The whole job in real time, the lab way: ``fleet world`` + ``fleet daemon --mission capture``
+ six ``fleet driver`` processes on 127.0.0.1 (the top-level fleet.toml's job with its goal
brought 2.5 m near: capture, route, re-arrangement and transport in a
minute of wall time instead of two and a half; ``sim.world = "process"``). The daemon plans
off its control loop, so the object is captured and delivered to ``object.goal`` with (almost)
no late tick and no watchdog stop of a robot while the controller drives it."""

from __future__ import annotations

import json
import re
import sys
import time
import tomllib

import pytest

from tests.support.config import ROOT, write_toml
from tests.support.lab import release, spawn, status, stop_all, tail
from tests.support.wait import wait_for

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

JOB_S = 300.0  # s of wall time the job may take (the dry run: about 40 s of sim time)
NEAR_GOAL = [4.5, 3.4, 0.0]


def lab_job_config(tmp_path, port: int):
    data = tomllib.loads((ROOT / "fleet.toml").read_text())
    data["object"]["goal"] = NEAR_GOAL
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data.setdefault("sim", {})["world"] = "process"
    data["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "lab-job.toml", data), [r["id"] for r in data["robots"]]


def _all_present(st: dict, ids: list[str]) -> bool:
    present = {r["id"] for r in st.get("robots", []) if r.get("present")}
    return bool(st.get("ok")) and present >= set(ids)


def _text(path) -> str:
    return path.read_text(errors="replace") if path.exists() else ""


def test_the_whole_job_delivers_in_real_time_under_world_daemon_and_drivers(tmp_path, port):
    cfg, ids = lab_job_config(tmp_path, port)
    c = str(cfg)
    world = spawn(tmp_path / "world.txt", "world", "--config", c)
    procs = [world]
    dlog = tmp_path / "daemon.txt"
    out = tmp_path / "daemon.mcap"
    t0 = time.monotonic()
    try:
        wait_for(lambda: "fleet world: fleet" in _text(tmp_path / "world.txt"), 30, "the world")
        daemon = spawn(dlog, "daemon", "--config", c, "--mission", "capture", "--out", str(out))
        procs.append(daemon)
        procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ids]
        # a fresh lab is stopped until an operator's first resume; the daemon must be up to
        # hear it (a holder's answer never releases a fresh daemon's latch)
        wait_for(lambda: _all_present(status(cfg), ids), 60, "the daemon and its robots")
        release(cfg, timeout=90)
        wait_for(lambda: daemon.poll() is not None, JOB_S, "the daemon's end of the job")
        wall = time.monotonic() - t0
    finally:
        codes = stop_all(procs)
    text = _text(dlog)
    assert codes[1] == 0, tail(daemon, 3000)  # the mission done (1: failed)
    done = re.search(r"^(\S+ \S+) INFO .*mission done in phase done", text, re.M)
    assert done, text[-3000:]
    end = done.group(1)
    health = re.search(r"(\d+) ticks, (\d+) late, (\d+) over the", text)
    assert health, text[-2000:]
    ticks, late_ticks, over = (int(g) for g in health.groups())
    # a late tick is the machine's scheduling, never a planner (they run in their own process):
    # measured 0 on a quiet machine, 1 of ~2 300 under a load of 4.5; one in a thousand allowed
    lags = re.findall(r".*control loop lag.*", text)
    assert late_ticks <= max(5, ticks // 1000), lags[:5]
    # (ticks over fleet.tick_budget are reported, not asserted: on 2 shared cores the other
    # processes' load decides them, measured 0.2-11 % of the ticks at 25-30 ms)
    # a robot stopped by its watchdog while the daemon still drove it: its commands came late
    # (after the job the daemon exits: the watchdogs stop the robots then, as they should)
    for r in ids:
        lines = _text(tmp_path / f"{r}.txt").splitlines()
        stops = [ln for ln in lines if "watchdog stop" in ln and ln[:23] < end]
        assert not stops, (r, stops[:3])
    rep = _replay(out)
    assert rep["transported"] is True, rep
    stopped = re.search(r"fleet daemon: stopped.*", text)
    print(f"\nlab job: {wall:.1f} s wall; {stopped.group(0)}; {json.dumps(rep)}", file=sys.stderr)


def _replay(path) -> dict:
    """What the daemon's log says of the transport (truth is the world's: sim/truth)."""
    import contextlib
    import io

    from controller.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        main(["replay", str(path), "--json"])
    return json.loads(buf.getvalue())
