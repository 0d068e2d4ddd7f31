"""The secure profile end to end, as separate processes: the daemon (hub: dictionary + lab
ACL), robot r1's agent under its own identity, and the tools as an operator and as a robot."""

from __future__ import annotations

import json
import time

import pytest

from tests.support.config import base_config_dict, free_port, write_toml
from tests.support.lab import fleet, spawn, status, stop_all

USERS = ["controller", "operator", "r1", "r2", "r3", "r4", "r5", "r6"]


@pytest.mark.parametrize("second_path", [False, True], ids=["hub", "hub+estop_listen"])
def test_operator_stops_and_resumes_a_robot_cannot(tmp_path, port, second_path):
    """Also with the e-stop's second path (``zenoh.estop_listen``): the daemon's router there
    checks the same passwords and ACL, so a robot's identity releases nothing by it either."""
    for u in USERS:
        (tmp_path / f"{u}.pw").write_text(f"pw-of-{u}\n")
    (tmp_path / "users.txt").write_text("".join(f"{u}:pw-of-{u}\n" for u in USERS))
    cfg = base_config_dict()
    cfg["zenoh"] = {
        "mode": "peer",
        "listen": [f"tcp/127.0.0.1:{port}"],
        "user": "controller",
        "password_file": "controller.pw",  # relative to the config file
        "auth_dictionary": "users.txt",
        "acl": "lab",
        "operators": ["operator"],
    }
    if second_path:
        cfg["zenoh"]["estop_listen"] = [f"tcp/127.0.0.1:{free_port()}"]
    cfg["robots"] = cfg["robots"][:1]  # the one agent this test runs (estop waits for all)
    for r in cfg["robots"]:
        r.update(zenoh_user=r["id"], zenoh_password_file=f"{r['id']}.pw")
    cfg["sim"]["backend"] = "ideal"
    # r1's world of its own, stepped at 50 Hz: only its poses matter here (at 240 Hz with the
    # moving crate's clearance checks it fell seconds behind on a loaded 2-core machine, its
    # poses then dropped as stamped in the past)
    cfg["sim"]["timestep"] = 0.02
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    conf = write_toml(tmp_path / "secure.toml", cfg)
    as_op = ["--user", "operator", "--password-file", str(tmp_path / "operator.pw")]
    as_r1 = ["--user", "r1", "--password-file", str(tmp_path / "r1.pw")]
    daemon = spawn(
        tmp_path / "daemon.txt", "daemon", "--config", str(conf), "--mission", "hold",
        "--out", str(tmp_path / "d.mcap"),
    )  # fmt: skip
    agent = spawn(tmp_path / "agent.txt", "driver", "r1", "--config", str(conf))
    try:
        deadline = time.monotonic() + 40
        st: dict = {"ok": False}
        while time.monotonic() < deadline:  # handshake: r1 present and its poses arrive
            st = status(conf)
            if st.get("ok") and st["counters"]["poses"] > 0:
                break
        assert st.get("ok") and st["counters"]["poses"] > 0, st
        assert any(r["id"] == "r1" and r["present"] for r in st["robots"])
        est = fleet("estop", "--config", str(conf), "--json", *as_op)
        assert est.returncode == 0 and json.loads(est.stdout)["confirmed"] is True, est.stdout
        # r1's identity may not release the e-stop: dropped at the hub, never confirmed
        res = fleet("resume", "--config", str(conf), "--json", "--timeout", "1.5", *as_r1)
        assert res.returncode == 1 and json.loads(res.stdout)["confirmed"] is False
        assert status(conf)["estop"] is True
        res = fleet("resume", "--config", str(conf), "--json", *as_op)
        assert res.returncode == 0 and json.loads(res.stdout)["confirmed"] is True
    finally:
        codes = stop_all([agent, daemon])
    assert codes == [0, 0], [open(p.log_path).read()[-2000:] for p in (agent, daemon)]
