"""One controller per fleet, as separate processes on 127.0.0.1 (issue 22, item 4): a second
``fleet daemon`` refuses to start, naming the running one; ``--take-over`` replaces it (the old
one stops commanding and exits 1 naming the newcomer), and ``fleet status`` names who answers."""

from __future__ import annotations

import signal

import pytest

from tests.support.lab import connect_client, fleet, fleet_json, lab_config, spawn, stop_all, tail
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e


def _status(cfg) -> dict:
    code, st = fleet_json("status", "--config", str(cfg), "--timeout", "1")
    return st if code == 0 else {"ok": False}


def _present(st: dict, rid: str) -> bool:
    return any(r["id"] == rid and r["present"] for r in st.get("robots", []))


def test_a_second_daemon_refuses_and_a_take_over_leaves_one_commanding(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    args = ("daemon", "--config", c, "--mission", "hold", "--out")
    first = spawn(tmp_path / "first.txt", *args, str(tmp_path / "first.mcap"))
    agent = spawn(tmp_path / "r1.txt", "driver", "r1", "--config", c)
    procs = [first, agent]
    try:
        # handshake: the daemon answers and sees the agent
        wait_for(lambda: _present(_status(cfg), "r1"), 40, "the first daemon and r1")
        st = _status(cfg)
        old = st["controller"]
        assert old.startswith("main-") and st["controllers"] == [old]

        # a second daemon: refused, naming the running one; the first goes on
        second = fleet(*args, str(tmp_path / "second.mcap"), timeout=60)
        assert second.returncode == 1, second.stderr
        assert old in second.stderr and "--take-over" in second.stderr
        assert first.poll() is None and _status(cfg)["controller"] == old

        # take-over: the old one stops and exits 1 naming the newcomer, which takes its place
        newcomer = spawn(tmp_path / "new.txt", *args, str(tmp_path / "new.mcap"), "--take-over")
        procs.append(newcomer)
        assert first.wait(timeout=30) == 1, tail(first)
        st = {}

        def answered_by_newcomer() -> bool:
            nonlocal st
            st = _status(cfg)
            return st.get("ok", False) and st["controller"] != old and _present(st, "r1")

        wait_for(answered_by_newcomer, 40, "the newcomer answering, r1 back")
        new = st["controller"]
        assert st["controllers"] == [new] and new > old  # one controller answers, newer
        assert new in tail(first) and "took over" in tail(first)
        assert newcomer.poll() is None and agent.poll() is None
        assert f"taking over fleet 'lab' from {old}" in tail(newcomer)
        # the newcomer's loop runs on
        ticks = st["counters"]["ticks"]
        wait_for(lambda: _status(cfg)["counters"]["ticks"] > ticks + 10, 10, "the loop ticking")
    finally:
        codes = stop_all(procs)
    assert codes[-1] == 0  # the newcomer stopped cleanly


def test_a_hung_daemon_taken_over_exits_when_it_resumes(tmp_path, port):
    """Through a hub: the old daemon hangs (SIGSTOP); a take-over waits for its token to expire
    (its lease), then runs; continued (SIGCONT), the old one sees the newer controller and
    exits 1 naming it, leaving the newcomer answering."""
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    args = ("daemon", "--config", c, "--mission", "hold", "--out")
    hub = spawn(tmp_path / "hub.txt", "hub", "--config", c)
    procs = [hub]
    try:
        first = spawn(tmp_path / "first.txt", *args, str(tmp_path / "first.mcap"))
        procs.append(first)
        wait_for(lambda: _status(cfg).get("ok", False), 40, "the first daemon")
        old = _status(cfg)["controller"]
        first.send_signal(signal.SIGSTOP)
        newcomer = spawn(tmp_path / "new.txt", *args, str(tmp_path / "new.mcap"), "--take-over")
        procs.append(newcomer)
        wait_for(lambda: _status(cfg).get("controller", old) != old, 40, "the newcomer answering")
        new = _status(cfg)["controller"]
        first.send_signal(signal.SIGCONT)
        assert first.wait(timeout=30) == 1, tail(first)
        assert f"controller {new} took over" in tail(first)
        st = _status(cfg)
        assert st["controllers"] == [new] and newcomer.poll() is None
    finally:
        stop_all(procs)


FORGED = "main-9999999999999-6-evil"  # stamped in the year 2286: one peer on the port can put it


def test_a_forged_controller_token_stamped_far_ahead_neither_stops_nor_hides_the_daemon(
    tmp_path, port
):
    """Open profile: a peer's liveliness token under alive/controller/ with a far-future stamp
    does not make the running daemon yield; a second daemon is refused with the reason named."""
    cfg = lab_config(tmp_path, port, robots=1)
    c = str(cfg)
    args = ("daemon", "--config", c, "--mission", "hold", "--out")
    hub = spawn(tmp_path / "hub.txt", "hub", "--config", c)
    procs = [hub]
    try:
        with connect_client(port, "the hub") as bus:
            daemon = spawn(tmp_path / "d.txt", *args, str(tmp_path / "d.mcap"))
            procs.append(daemon)
            wait_for(lambda: _status(cfg).get("ok"), 40, "the daemon")
            own = _status(cfg)["controller"]
            bus.declare_alive("controller", FORGED)
            wait_for(lambda: "stamped" in tail(daemon) and FORGED in tail(daemon), 10, "its log")
            ticks = _status(cfg)["counters"]["ticks"]
            wait_for(lambda: _status(cfg)["counters"]["ticks"] > ticks + 10, 10, "ticks")
            assert daemon.poll() is None and _status(cfg)["controller"] == own
            second = fleet(*args, str(tmp_path / "second.mcap"), timeout=60)
            assert second.returncode == 1 and "stamped far in the future" in second.stderr
    finally:
        stop_all(procs)
