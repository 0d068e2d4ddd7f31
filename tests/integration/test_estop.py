"""The e-stop that cannot be forgotten, as separate processes on 127.0.0.1: ``fleet hub``, the
daemon, robot agents and the ``fleet estop|resume`` tools. The e-stop reaches every agent with
the daemon alive, hung (SIGSTOP) and dead; it is latched (a late agent and a restarted daemon
come up stopped) until ``fleet resume``; an agent that is not running is named."""

from __future__ import annotations

import signal

from tests.support.lab import (
    connect_client,
    fleet_json,
    lab_config,
    latch_states,
    spawn,
    stop_all,
    tail,
)
from tests.support.wait import wait_for


def _status(cfg) -> dict:
    code, st = fleet_json("status", "--config", str(cfg), "--timeout", "1")
    return st if code == 0 else {"ok": False}


def _estop(cfg, word: str, timeout: float = 5.0) -> tuple[int, dict]:
    return fleet_json(word, "--config", str(cfg), "--timeout", str(timeout))


def _all_hold(bus, ids, engaged: bool) -> bool:
    states = latch_states(bus, timeout=0.5)
    return all(f"robot/{r}" in states and states[f"robot/{r}"].engaged == engaged for r in ids)


def test_estop_reaches_agents_with_daemon_alive_hung_dead_and_stays_latched(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=3)
    c = str(cfg)
    hub = spawn(tmp_path / "hub.txt", "hub", "--config", c)
    procs = [hub]
    try:
        bus = connect_client(port, "the hub")
        with bus:
            daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")
            daemon = spawn(tmp_path / "daemon.txt", *daemon_args, str(tmp_path / "d1.mcap"))
            agents = {
                r: spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")
            }
            procs += [daemon, *agents.values()]
            # handshake: the daemon answers and sees both agents' poses; both agents hold a latch
            wait_for(
                lambda: (
                    (st := _status(cfg)).get("ok")
                    and sum(r["present"] for r in st["robots"]) == 2
                    and st["counters"]["poses"] > 0
                ),
                40,
                "the daemon seeing r1 and r2",
            )
            # a fresh lab fails closed until an operator's first resume (r3 is not running)
            code, out = _estop(cfg, "resume", timeout=1.0)
            assert out["agents_confirmed"] == ["r1", "r2"] and out["agents_missing"] == ["r3"]
            wait_for(lambda: _all_hold(bus, ("r1", "r2"), False), 10, "the agents' latches")

            # daemon alive; r3 is in the config but not running: named, exit 1
            code, out = _estop(cfg, "estop", timeout=1.0)
            assert code == 1 and out["agents_missing"] == ["r3"], out
            assert out["agents_confirmed"] == ["r1", "r2"] and out["confirmed"] is False
            assert out["command"] == "estop" and out["engaged"] is True and "phase" in out
            wait_for(lambda: _status(cfg).get("estop") is True, 10, "the daemon engaged")

            # a late agent comes up stopped
            procs.append(spawn(tmp_path / "r3.txt", "driver", "r3", "--config", c))
            wait_for(lambda: _all_hold(bus, ("r1", "r2", "r3"), True), 20, "r3 up, stopped")

            code, out = _estop(cfg, "resume")
            assert code == 0 and out["confirmed"] is True and out["agents_missing"] == [], out
            assert _all_hold(bus, ("r1", "r2", "r3"), False)
            wait_for(lambda: _status(cfg).get("estop") is False, 10, "the daemon released")

            # daemon hung: the e-stop still reaches every agent; the daemon comes back stopped
            daemon.send_signal(signal.SIGSTOP)
            code, out = _estop(cfg, "estop")
            assert code == 0 and out["agents_confirmed"] == ["r1", "r2", "r3"], out
            assert out["daemon_confirmed"] is False
            # hung past its lease: the hub drops it (and the e-stop it was sent with it)
            wait_for(lambda: not bus.alive_ids("controller", 0.5), 10, "lease expiry")
            daemon.send_signal(signal.SIGCONT)
            wait_for(lambda: _status(cfg).get("estop") is True, 15, "the resumed daemon stopped")
            code, out = _estop(cfg, "resume")
            assert code == 0, out
            wait_for(lambda: _status(cfg).get("estop") is False, 10, "the daemon released")

            # daemon dead: the e-stop reaches every agent; a restarted daemon comes up stopped
            daemon.kill()
            daemon.wait()
            code, out = _estop(cfg, "estop")
            assert code == 0 and out["agents_confirmed"] == ["r1", "r2", "r3"], out
            daemon2 = spawn(tmp_path / "daemon2.txt", *daemon_args, str(tmp_path / "d2.mcap"))
            procs.append(daemon2)
            wait_for(lambda: _status(cfg).get("ok"), 40, "the restarted daemon")
            st = _status(cfg)
            assert st["estop"] is True, st
            # only resume lifts it
            assert _all_hold(bus, ("r1", "r2", "r3"), True)
            code, out = _estop(cfg, "resume")
            assert code == 0, out
            wait_for(lambda: _status(cfg).get("estop") is False, 10, "the daemon released")
            states = latch_states(bus)
            assert states["hub/main"].engaged is False
    finally:
        codes = stop_all(procs)
    assert all(code in (0, -9) for code in codes), (codes, [tail(p) for p in procs])
