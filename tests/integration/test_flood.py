"""Floods against the lab daemon, as separate processes on 127.0.0.1 (issue 22, item 5): a
flood of believable poses at 10x the normal pose rate on every robot's key, and a flood of
4 MiB payloads. The daemon's loop keeps its rate (its own late-tick counters), the flood is
counted where it is dropped, and no robot's watchdog fires for it (commands keep arriving).
The machine is shared: late ticks and watchdog stops are compared with a window of the same
harness at the normal pose rate."""

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


def _flood(port: int, cfg, kind: str, rate: float, robots=None) -> dict:
    """Flood ``robots``' pose keys (default: every robot's) at ``rate`` for SECONDS."""
    robots = cfg.robots if robots is None else robots
    where = ";".join(",".join(str(v) for v in r.start) for r in robots)
    ids = ",".join(r.id for r in robots)
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


def _log_sizes(agents) -> list[int]:
    return [len(tail(a, 10**9)) for a in agents]


def _stops(agents, start: list[int], end: list[int]) -> int:
    """Watchdog stops the agents logged between two marks of their logs."""
    return sum(
        tail(a, 10**9)[i:j].count("watchdog stop")
        for a, i, j in zip(agents, start, end, strict=True)
    )


def _window(before: dict, after: dict) -> tuple[int, int]:
    """(ticks, ticks late or periods skipped) between two status answers."""
    late = _delta(before, after, "late_ticks") + _delta(before, after, "skipped_ticks")
    return _delta(before, after, "ticks"), late


def _kept_its_rate(flood: tuple[int, int], quiet: tuple[int, int], expected: float) -> None:
    """The loop ticked at its rate through the flood: (nearly) every tick ran, and no more
    ticks were late than in a window of the same length at the normal rate (the machine is
    shared: a loaded one delays ticks now and then, flood or not; the old bus skipped 25-34
    periods in 3 s under a full-rate flood, bench/bus.py --flood)."""
    assert flood[0] >= 0.9 * expected, (flood, expected)
    assert flood[1] <= quiet[1] + max(3, 0.1 * flood[0]), (flood, quiet)


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

        marks = [_log_sizes(agents)]
        expected_ticks = cfg.fleet.rate_hz * SECONDS
        # the baseline: the same harness putting poses at the normal rate
        before = _status(path)
        _flood(port, cfg, "poses", rate)
        quiet = _window(before, _status(path))
        marks.append(_log_sizes(agents))

        # 10x the normal pose rate on every robot's key
        before = _status(path)
        sent = _flood(port, cfg, "poses", 10 * rate)
        after = _status(path)
        # (the flooder is paced at 10x; on a loaded machine it may fall short: still a flood)
        assert sent["sent"] >= 2 * rate * SECONDS * len(cfg.robots), sent
        _kept_its_rate(_window(before, after), quiet, expected_ticks)
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
        _kept_its_rate(_window(before, after), quiet, expected_ticks)
        assert _delta(before, after, "poses") > 0  # the real poses still come in
        marks.append(_log_sizes(agents))
        # no robot's watchdog fired for the floods: no more stops than in the baseline window
        # (a loaded machine can delay a command past cmd_ttl, flood or not) + 1; a stalled
        # loop stops every robot
        stops_quiet = _stops(agents, marks[0], marks[1])
        stops_flood = _stops(agents, marks[1], marks[2])
        assert stops_flood <= stops_quiet + 1, (stops_flood, stops_quiet)

        # one robot floods its own pose key as fast as a process can put (tens of kHz): the
        # daemon reads each robot's poses from a zenoh ring at each tick (no Python callback
        # per sample), at most zenoh.inbox_depth a tick; the rest is overwritten unread and
        # counted; the loop keeps its rate and the other robot's watchdog never fires
        # (issue 31 5c: with a callback per sample 10-15 of ~100 ticks came late here on the
        # loaded 2-core CI machine)
        r1 = cfg.robots[0]
        before = _status(path)
        sent = _flood(port, cfg, "poses", 1e6, [r1])  # as fast as it can put
        after = _status(path)
        read = cfg.zenoh.inbox_depth * cfg.fleet.rate_hz * SECONDS  # the most r1's ring gives
        assert sent["sent"] > 10 * read, sent  # a flood beyond it
        dropped = _delta(before, after, "inbox_overflow")
        taken = _delta(before, after, "poses")
        # taken in: r1's ring at every tick (the flooder's start-up included) and both robots'
        # own poses over the window
        most = read + cfg.zenoh.inbox_depth * 5 * cfg.fleet.rate_hz + 2 * rate * (SECONDS + 5)
        assert taken <= most, (taken, most)
        assert dropped > 0.5 * (sent["sent"] - read), (dropped, taken, sent)
        _kept_its_rate(_window(before, after), quiet, expected_ticks)
        marks.append(_log_sizes(agents))
        others = agents[1:]
        assert _stops(others, marks[2][1:], marks[3][1:]) == 0, [tail(a) for a in others]
        assert all(a.poll() is None for a in agents)
    finally:
        stop_all(procs)
