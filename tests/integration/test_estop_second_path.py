"""The e-stop's second path (issue 31 item 3), as separate processes on 127.0.0.1: with
``zenoh.estop_listen`` the daemon also listens there, a router of its own for the e-stop alone;
every agent and ``fleet estop|resume|status`` connect there too. With the hub hung (SIGSTOP)
``fleet estop`` still reaches every agent, confirmed within a second, ``fleet status`` still
answers, and the daemon's log keeps the e-stop; without the second path the same e-stop reached
no robot (the tool waited 10 s for the hub's handshake, then exit 1)."""

from __future__ import annotations

import json
import signal
import time

from tests.support.config import free_port
from tests.support.lab import (
    connect_client,
    fleet_json,
    lab_config,
    latch_states,
    release,
    spawn,
    stop_all,
)
from tests.support.wait import wait_for


def _status(cfg) -> dict:
    code, st = fleet_json("status", "--config", str(cfg), "--timeout", "1")
    return st if code == 0 else {"ok": False}


def _holders(bus) -> dict:
    return {k: v.engaged for k, v in latch_states(bus, timeout=0.5).items()}


def test_estop_reaches_every_agent_through_the_daemon_with_the_hub_hung(tmp_path, port):
    second = free_port()
    cfg = lab_config(tmp_path, port, zenoh={"estop_listen": [f"tcp/127.0.0.1:{second}"]})
    c = str(cfg)
    hub = spawn(tmp_path / "hub.txt", "hub", "--config", c)
    procs = [hub]
    try:
        with connect_client(port, "the hub"):
            log = tmp_path / "daemon.mcap"
            daemon = spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission", "hold",
                           "--out", str(log))  # fmt: skip
            agents = [
                spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")
            ]
            procs += [daemon, *agents]
            wait_for(
                lambda: (st := _status(cfg)).get("ok") and all(r["present"] for r in st["robots"]),
                40,
                "the daemon seeing r1 and r2",
            )
            release(cfg)
        # the handshake of the second path: the daemon and both agents answer there
        with connect_client(second, "the daemon's e-stop listener") as path:
            wanted = {"controller/main": False, "robot/r1": False, "robot/r2": False}
            wait_for(lambda: _holders(path) == wanted, 20, "every holder on the second path")

            hub.send_signal(signal.SIGSTOP)  # the hub hangs: its path carries nothing
            t0 = time.monotonic()
            code, out = fleet_json("estop", "--config", c, "--timeout", "5", "--reason", "hub hung")
            took = time.monotonic() - t0
            print(f"hub hung: confirmed in {out['elapsed_s']} s, the tool took {took:.2f} s")
            assert code == 0 and out["confirmed"] is True, json.dumps(out)
            assert out["agents_confirmed"] == ["r1", "r2"] and out["daemon_confirmed"] is True
            # confirmed by both agents within a second of the put (the tool's own start-up and
            # the hung hub's handshake, which it gives up after 2 s, come on top)
            assert out["elapsed_s"] < 1.0, out
            assert took < 10.0, took  # the old tool waited 10 s for the hub, then exit 1
            engaged = {k: True for k in wanted}
            assert _holders(path) == engaged  # the latch held, answered on the second path
            # the operator still sees the fleet: fleet status answers by the second path
            st = _status(cfg)
            assert st.get("ok") and st["estop"] is True, st
            assert all(r["present"] for r in st["robots"]), st

            # the hub back: it learns the engaged latch from the holders, and a resume releases
            hub.send_signal(signal.SIGCONT)
            with connect_client(port, "the hub again") as bus:
                wait_for(lambda: _holders(bus).get("hub/main") is True, 15, "the hub engaged")
            out = release(cfg)
            assert out["agents_confirmed"] == ["r1", "r2"], out
            wait_for(lambda: _holders(path) == wanted, 10, "every holder released")
    finally:
        codes = stop_all(procs)
    assert codes[1] == 0, codes  # the daemon stopped cleanly: its log is whole
    # the e-stop that came by the second path alone is in the daemon's log (once per put: the
    # tool repeats it until confirmed; one put by both paths is logged once, tests/unit/
    # test_two_path_tap.py)
    reasons = [json.loads(m.data).get("reason") for m in _messages(log, "fleet/lab/estop")]
    assert reasons.count("hub hung") >= 1, reasons


def _messages(path, topic: str) -> list:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [m for _, ch, m in make_reader(f).iter_messages() if ch.topic == topic]
