"""Floods against the lab daemon, as separate processes on 127.0.0.1 (issue 22, item 5): a
flood of believable poses at 10x the normal pose rate on every robot's key, and a flood of
4 MiB payloads. The daemon's loop keeps its rate (its own late-tick counter), the flood is
counted where it is dropped, and no robot's watchdog fires (commands keep arriving)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from controller.config import load_config
from tests.support.config import ROOT
from tests.support.lab import fleet_json, lab_config, spawn, stop_all, tail
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

SECONDS = 3.0


def _status(cfg) -> dict:
    code, st = fleet_json("status", "--config", str(cfg), "--timeout", "1")
    return st if code == 0 else {"ok": False}


def _flood(port: int, cfg, kind: str, rate: float) -> dict:
    where = ";".join(",".join(str(v) for v in r.start) for r in cfg.robots)
    ids = ",".join(cfg.robot_ids)
    proc = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "support" / "flooder.py")]
        + [f"tcp/127.0.0.1:{port}", cfg.fleet.name, ids, str(rate), str(SECONDS), kind, where],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _delta(a: dict, b: dict, key: str) -> int:
    return b["counters"].get(key, 0) - a["counters"].get(key, 0)


def test_the_daemon_keeps_its_rate_under_a_pose_flood_and_4_mib_payloads(tmp_path, port):
    path = lab_config(tmp_path, port, robots=2)
    cfg = load_config(str(path))
    c = str(path)
    daemon = spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission", "hold")
    agents = [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in cfg.robot_ids]
    procs = [daemon, *agents]
    rate = cfg.sim.pose_rate_hz  # each agent's pose rate
    try:

        def ready() -> bool:
            st = _status(path)
            robots = st.get("robots", [])
            return bool(robots) and all(r["present"] for r in robots) and st["counters"]["poses"]

        wait_for(ready, 40, "the daemon seeing both robots' poses")

        # 10x the normal pose rate on every robot's key
        logged = [len(tail(a, 10**9)) for a in agents]  # the agents' logs so far
        before = _status(path)
        sent = _flood(port, cfg, "poses", 10 * rate)
        after = _status(path)
        expected_ticks = cfg.fleet.rate_hz * SECONDS
        assert sent["sent"] >= 0.8 * 10 * rate * SECONDS * len(cfg.robots), sent
        assert _delta(before, after, "ticks") >= 0.9 * expected_ticks
        assert _delta(before, after, "late_ticks") <= 2, (before, after)
        assert _delta(before, after, "skipped_ticks") == 0
        # the flood was taken in or counted, never queued without end
        taken = _delta(before, after, "poses") + _delta(before, after, "inbox_overflow")
        assert taken >= 0.8 * sent["sent"]

        # 4 MiB payloads: dropped unread, counted once each
        before = after
        sent = _flood(port, cfg, "big", 10.0)
        wait_for(
            lambda: _delta(before, _status(path), "oversize_payloads") == sent["sent"],
            10,
            "every 4 MiB payload counted",
        )
        after = _status(path)
        assert _delta(before, after, "ticks") >= 0.9 * cfg.fleet.rate_hz * SECONDS
        assert _delta(before, after, "late_ticks") <= 2, (before, after)
        assert _delta(before, after, "poses") > 0  # the real poses still come in
        for a, n in zip(agents, logged, strict=True):
            since = tail(a, 10**9)[n:]  # what the agent logged during both floods
            assert a.poll() is None and "watchdog stop" not in since, since
    finally:
        stop_all(procs)
