"""The lab path as separate processes: daemon, a robot agent, and the status/estop/resume tools."""

from __future__ import annotations

import json
import time

import pytest

from controller.io.recorder import read_log
from tests.support.config import base_config_dict, write_toml
from tests.support.lab import fleet, release, spawn, status, stop_all


@pytest.fixture
def lab_config(tmp_path, port):
    cfg = base_config_dict()
    # one robot: `fleet estop` is confirmed only when every robot of the config confirms
    cfg["robots"] = cfg["robots"][:1]
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    cfg["sim"]["backend"] = "ideal"
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "lab.toml", cfg)


def test_daemon_agent_status_estop_resume(lab_config, tmp_path):
    log = tmp_path / "daemon.mcap"
    daemon = spawn(
        tmp_path / "daemon.txt",
        "daemon",
        "--config",
        str(lab_config),
        "--mission",
        "hold",
        "--out",
        str(log),
    )
    agent = spawn(tmp_path / "agent.txt", "driver", "r1", "--config", str(lab_config))
    try:
        deadline = time.monotonic() + 40
        st = {"ok": False}
        while time.monotonic() < deadline:
            # handshake: the daemon reports r1 present and has received its poses (the
            # liveliness token can arrive before the first pose sample)
            st = status(lab_config)
            if (
                st.get("ok")
                and any(r["id"] == "r1" and r["present"] for r in st["robots"])
                and st["counters"]["poses"] > 0
            ):
                break
        assert st.get("ok"), "the daemon never answered fleet status"
        # a fresh lab fails closed: the latch unknown, the robots stopped, until an operator
        assert st["phase"] == "hold" and st["estop"] is True and st["counters"]["estop_unknown"]
        release(lab_config)
        assert status(lab_config)["estop"] is False
        assert any(r["id"] == "r1" and r["present"] for r in st["robots"])
        assert st["counters"]["poses"] > 0, st  # r1's poses reach the daemon
        est = fleet("estop", "--config", str(lab_config), "--json", "--reason", "test")
        assert est.returncode == 0, est.stderr
        assert json.loads(est.stdout)["confirmed"] is True
        assert status(lab_config)["estop"] is True
        res = fleet("resume", "--config", str(lab_config), "--json")
        assert res.returncode == 0 and json.loads(res.stdout)["confirmed"] is True
        assert status(lab_config)["estop"] is False
    finally:
        codes = stop_all([agent, daemon])  # never leave a process behind
    assert codes == [0, 0], [open(p.log_path).read()[-2000:] for p in (agent, daemon)]
    topics = {r.topic for r in read_log(log)}
    assert "fleet/lab/robot/r1/pose" in topics and "fleet/lab/estop" in topics


def test_status_without_daemon_exits_1(lab_config):
    proc = fleet("status", "--config", str(lab_config), "--timeout", "0.5")
    assert proc.returncode == 1 and "no daemon" in proc.stderr


def test_driver_for_unanswering_mavlink_robot_exits_1(tmp_path, port):
    from tests.support.mavlink_rig import free_udp_port

    cfg = base_config_dict()
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    udp = free_udp_port()
    cfg["robots"][2].update(
        driver="mavlink", profile="ardurover", url=f"udpin:127.0.0.1:{udp}", system_id=3
    )
    path = write_toml(tmp_path / "m.toml", cfg)
    proc = fleet("driver", "r3", "--config", str(path), "--connect-timeout", "0.5")
    assert proc.returncode == 1
    assert f"udpin:127.0.0.1:{udp}" in proc.stderr and "system 3" in proc.stderr
