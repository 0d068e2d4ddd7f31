"""`fleet run` as a user calls it: the summary contract, exit codes."""

from __future__ import annotations

import json

from controller.cli import main
from tests.support.config import base_config_dict, free_port, write_toml

FIELDS = (
    "status", "phase", "arrested", "arrest_time_s", "arrival_spread_s", "min_clearance_m",
    "max_object_penetration_m", "obstacle_contacts", "sim_time_s", "wall_time_s", "log",
)  # fmt: skip


def config(tmp_path, robots: int = 6):
    cfg = base_config_dict()
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": []}
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    cfg["robots"] = cfg["robots"][:robots]
    return write_toml(tmp_path / "fleet.toml", cfg)


def test_run_json_summary_and_exit_0(tmp_path, capsys):
    path = config(tmp_path)
    code = main(["run", "--config", str(path), "--backend", "ideal", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out
    for k in FIELDS:
        assert k in out, k
    assert out["status"] == "ok" and out["arrested"] is True
    assert out["arrest_time_s"] > 0 and out["arrival_spread_s"] >= 0
    assert out["log"].startswith(str(tmp_path / "runs")) and out["log"].endswith(".mcap")
    # the log replays into the same verdict
    assert main(["replay", out["log"], "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["arrested"] is True and rep["arrest_time_s"] is not None


def test_run_that_times_out_exits_1(tmp_path, capsys):
    path = config(tmp_path)
    code = main(["run", "--config", str(path), "--backend", "ideal", "--json", "--max-time", "2"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["status"] == "failed" and out["arrested"] is False


def test_run_with_too_few_robots_exits_1_naming_both_numbers(tmp_path, capsys):
    path = config(tmp_path, robots=3)
    assert main(["run", "--config", str(path), "--backend", "ideal"]) == 1
    err = capsys.readouterr().err
    assert "needs 4" in err and "has 3" in err
