"""Issue 31 (items 1 and 2), as separate processes on 127.0.0.1 (``fleet hub``, the daemon, two
robot agents, the ``fleet estop|resume|status`` tools):

- the state folder stops taking writes while the fleet runs: ``fleet estop`` stops every robot
  but says ``durable: false`` naming the hub and the daemon (exit 3), ``fleet status`` shows it,
  ``fleet resume`` is refused (robots stay held); every process killed (-9) and started again
  with the folder still broken: the robots stay stopped; once the folder takes writes again,
  the operator's resume goes through.
- one robot's credentials answer "engaged at 2^63-1" on its latch key: the fleet stops (a robot
  may stop it), and the operator's next resume still releases every agent.

How the folder is made to refuse writes, for root too (chmod is no obstacle to root, and
``prlimit --fsize`` would hit every file the process writes, the MCAP log included): the latch's
temporary file (``estop-<fleet>-<holder>.json.tmp``, written before the rename) is made a
directory. Every write of the latch then fails with EISDIR, as on a full disk or a read-only
folder, and nothing else of the process is touched.
"""

from __future__ import annotations

import json
import threading

import pytest

from controller import wire
from tests.support.lab import (
    connect_client,
    fleet_json,
    lab_config,
    latch_states,
    spawn,
    status,
    stop_all,
    tail,
)
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

ROBOTS = ("r1", "r2")
HOLDERS = ("controller/main", "hub/main")
NOT_DURABLE = 3  # fleet estop|resume's exit status: confirmed, but not kept (or refused)


def _start(tmp_path, c: str, n: int) -> list:
    daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")
    procs = [spawn(tmp_path / f"hub{n}.txt", "hub", "--config", c)]
    procs.append(spawn(tmp_path / f"d{n}.txt", *daemon_args, str(tmp_path / f"d{n}.mcap")))
    procs += [spawn(tmp_path / f"{r}-{n}.txt", "driver", r, "--config", c) for r in ROBOTS]
    return procs


def _put(cfg, word: str, timeout: float = 10.0) -> tuple[int, dict]:
    """``fleet estop|resume --json``; (exit status, its JSON). A put that a holder cannot keep
    waits its whole timeout for it to become durable: 10 s also covers a loaded machine."""
    return fleet_json(word, "--config", str(cfg), "--timeout", str(timeout))


def _agents(bus, engaged: bool) -> bool:
    """Whether both agents hold ``engaged`` (an impostor's answers, source "forged", aside)."""
    held = {}
    for key, msg in bus.query_replies(bus.estop_wildcard(), wire.EStop, 0.5):
        parsed = wire.parse_key(key, bus.fleet)
        if parsed is not None and msg.source != "forged":
            held[parsed.id] = msg.engaged
    return all(held.get(r) == engaged for r in ROBOTS)


def _break(folder) -> None:
    """Every write of the hub's and the daemon's latch fails from now on (EISDIR)."""
    for h in ("hub", "controller"):
        (folder / f"estop-lab-{h}.json.tmp").mkdir()


def _mend(folder) -> None:
    for h in ("hub", "controller"):
        (folder / f"estop-lab-{h}.json.tmp").rmdir()


def _kept(folder, holder: str, engaged: bool) -> bool:
    path = folder / f"estop-lab-{holder}.json"
    return path.exists() and wire.decode(wire.EStop, path.read_bytes()).engaged == engaged


def test_an_estop_that_cannot_be_kept_says_so_and_survives_a_full_restart(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    folder = tmp_path / "state"  # the default: beside the config, not in log.dir
    procs = _start(tmp_path, c, 1)
    try:
        bus = connect_client(port, "the hub")
        with bus:
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
            code, out = _put(cfg, "resume", timeout=30)
            assert code == 0 and out["durable"] is True and out["not_durable"] == [], out
            assert {h["holder"] for h in out["holders"]} >= {*HOLDERS, "robot/r1", "robot/r2"}
            wait_for(lambda: _kept(folder, "hub", False), 10, "the hub's file")
            wait_for(lambda: _kept(folder, "controller", False), 10, "the daemon's file")
            assert not list((tmp_path / "runs").glob("estop-*"))  # not in the log folder

            _break(folder)
            code, out = _put(cfg, "estop")
            assert code == NOT_DURABLE, json.dumps(out)
            assert out["confirmed"] is True and out["agents_confirmed"] == list(ROBOTS), out
            assert out["durable"] is False and out["not_durable"] == list(HOLDERS), out
            kept = {h["holder"]: h for h in out["holders"]}
            assert kept["hub/main"]["engaged"] and kept["hub/main"]["durable"] is False, out
            assert kept["hub/main"]["epoch"] == out["epoch"]
            assert _kept(folder, "hub", False)  # the stale release is what the disk holds
            st = status(cfg)
            assert st["estop"] is True and st["estop_durable"] is False, st
            assert st["estop_not_durable"] == list(HOLDERS)
            assert st["counters"]["estop_durable"] == 0

            code, out = _put(cfg, "resume")
            assert code == NOT_DURABLE and out["refused"], out
            assert out["not_durable"] == list(HOLDERS) and out["agents_confirmed"] == [], out
            assert _agents(bus, engaged=True), latch_states(bus)  # the robots stay held
            assert status(cfg)["estop"] is True

        # a power cut: every process killed at once, started again, the folder still broken
        for p in procs:
            p.kill()
            p.wait()
        procs += _start(tmp_path, c, 2)
        bus = connect_client(port, "the restarted hub")
        with bus:
            wait_for(lambda: status(cfg).get("ok"), 40, "the restarted daemon")
            wait_for(lambda: _agents(bus, engaged=True), 20, "both agents' latches")
            st = status(cfg)
            assert st["estop"] is True and st["estop_durable"] is False, st
            code, out = _put(cfg, "resume")
            assert code == NOT_DURABLE and out["refused"], out
            assert _agents(bus, engaged=True), latch_states(bus)

            # the folder takes writes again: the engage is kept, then the operator resumes
            _mend(folder)
            wait_for(lambda: _kept(folder, "hub", True), 10, "the hub keeping the e-stop")
            wait_for(lambda: _kept(folder, "controller", True), 10, "the daemon keeping it")
            code, out = _put(cfg, "resume", timeout=30)
            assert code == 0 and out["durable"] is True and out["confirmed"] is True, out
            wait_for(lambda: _agents(bus, engaged=False), 10, "both agents released")
    finally:
        codes = stop_all(procs)
    assert all(code in (0, -9) for code in codes), (codes, [tail(p) for p in procs])


def test_a_robots_engage_at_max_seq_does_not_lock_the_fleet_stopped(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=2)
    procs = _start(tmp_path, str(cfg), 1)
    asked = [0]
    lock = threading.Lock()

    def forged() -> wire.EStop:
        with lock:
            asked[0] += 1
        return wire.EStop(t=0.0, engaged=True, source="forged", epoch=wire.MAX_SEQ)

    try:
        bus = connect_client(port, "the hub")
        with bus:
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
            code, out = _put(cfg, "resume", timeout=30)
            assert code == 0, out
            before = out["epoch"]
            attacker = connect_client(port, "the hub, as r1")
            with attacker:
                attacker.serve("estop_state", forged, role="robot", id="r1")
                # handshake: the hub and the agents ask every 2 s; 6 answers ≈ 2 rounds
                wait_for(lambda: asked[0] >= 6, 20, "the forged answer asked for")
                states = latch_states(bus)
                assert all(m.epoch <= before + 1 for m in states.values() if m.source != "forged")
                code, out = _put(cfg, "resume", timeout=30)
                assert code == 0 and out["confirmed"] is True, out
                assert out["agents_confirmed"] == list(ROBOTS), out
                assert before < out["epoch"] <= before + 2, out
                forged_seen = [h for h in out["holders"] if h["source"] == "forged"]
                assert forged_seen and forged_seen[0]["epoch"] == wire.MAX_SEQ, out
                assert _agents(bus, engaged=False), latch_states(bus)
                assert status(cfg)["estop"] is False
    finally:
        codes = stop_all(procs)
    assert all(code == 0 for code in codes), (codes, [tail(p) for p in procs])
