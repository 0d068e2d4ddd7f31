"""`fleet run` as a user calls it: the summary contract, exit codes."""

from __future__ import annotations

import json
import re

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


def test_run_in_text_ends_with_the_verdict_the_figures_and_the_next_steps(tmp_path, capsys):
    """Without --json: the outcome on stdout (the progress stays on stderr), the verdict line
    first, naming the reason and the phase; figures with units, no Python reprs."""
    path = config(tmp_path)
    code = main(["run", "--config", str(path), "--backend", "ideal", "--max-time", "2"])
    out = capsys.readouterr()
    assert code == 1
    lines = out.out.splitlines()
    assert re.match(r"FAILED timeout at 2\.\d s: sim time ran out .* in phase approach; ", lines[0])
    assert "of sim time in" in lines[0]
    assert re.search(r"^  min_clearance_m +\S+ m \(margin 0\.05 m: (ok|UNDER)\)$", out.out, re.M)
    assert re.search(r"^  sim_time_s +2\.\d+ s$", out.out, re.M)
    assert "{" not in out.out and "None" not in out.out
    assert "next:" in lines and any("--plots" in ln for ln in lines)
    assert "fleet run:" in out.err and "fleet run:" not in out.out


def test_run_with_too_few_robots_exits_1_naming_both_numbers(tmp_path, capsys):
    path = config(tmp_path, robots=3)
    assert main(["run", "--config", str(path), "--backend", "ideal"]) == 1
    err = capsys.readouterr().err
    assert "needs 4" in err and "has 3" in err


def test_gui_without_a_display_exits_2_before_anything_starts(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    path = config(tmp_path)
    assert main(["run", "--config", str(path), "--gui", "--json"]) == 2
    out = capsys.readouterr()
    assert json.loads(out.out)["exit"] == 2
    assert "--gui: no display (DISPLAY is not set)" in out.err
    assert not (tmp_path / "runs").exists()  # no log: nothing started


def test_gui_with_a_backend_that_has_no_window_exits_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("DISPLAY", ":0")
    path = config(tmp_path)
    assert main(["run", "--config", str(path), "--gui", "--backend", "ideal"]) == 2
    assert "the 'ideal' backend has no window" in capsys.readouterr().err


def test_sweep_runs_each_config_on_a_free_port(tmp_path, capsys):
    from controller.config import ZenohSection
    from controller.io.bus import Bus

    taken = free_port()
    paths = []
    for name in ("a", "b"):
        cfg = base_config_dict()
        cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{taken}"], "connect": []}
        cfg["sim"]["backend"] = "ideal"
        paths.append(str(write_toml(tmp_path / f"{name}.toml", cfg)))
    out_dir = tmp_path / "sweep"
    # the configs' own port is busy: a sweep that did not pick free ports could not run them
    with Bus(ZenohSection(), "other", listen=[f"tcp/127.0.0.1:{taken}"], connect=[]):
        code = main(["sweep", *paths, "--max-time", "1", "--json", "--out-dir", str(out_dir)])
    out = capsys.readouterr()
    r = json.loads(out.out)
    assert code == 1  # both time out: a failed run makes the sweep fail
    assert [row["config"] for row in r["runs"]] == paths and r["failed"] == 2
    assert all(row["status"] == "failed" and row["reason"] == "timeout" for row in r["runs"])
    assert all((out_dir / f"{i:02d}-{n}.mcap").is_file() for i, n in ((1, "a"), (2, "b")))
    lines = [ln for ln in out.err.splitlines() if ln.startswith("[") and "failed" in ln]
    assert len(lines) == 2  # one summary line per run, its verdict: the reason, the phase
    verdict = r"FAILED timeout at 1\.\d s: sim time ran out \([\d.]+ s\) in phase \w+"
    assert all(re.search(verdict, ln) for ln in lines), lines
    assert all(row["verdict_line"].startswith("FAILED timeout") for row in r["runs"])


def test_sweep_table_and_bad_config(tmp_path, capsys):
    from controller.runtime.sweep import table

    rows = [
        {"config": "a.toml", "status": "ok", "phase": "done", "sim_time_s": 16.5, "log": "x"},
        {"config": "b.toml", "status": "failed", "phase": "failed", "reason": "timeout"},
    ]
    text = table(rows)
    assert "a.toml" in text and "timeout" in text and text.endswith("1 of 2 runs ok")
    bad = tmp_path / "bad.toml"
    bad.write_text("[fleet]\nname = 'x'\nrate_hz = -1\n")
    good = config(tmp_path)
    assert main(["sweep", str(good), str(bad), "--out-dir", str(tmp_path / "s")]) == 2
    assert not (tmp_path / "s").exists()  # checked before anything ran


def test_run_with_the_live_view(tmp_path, capsys):
    data = base_config_dict()
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": []}
    data["log"] = {"dir": str(tmp_path / "runs")}
    data["viz"] = {"port": 0}  # any free port: the URL is printed
    path = write_toml(tmp_path / "viz.toml", data)
    code = main(["run", "--config", str(path), "--backend", "ideal", "--viz", "--max-time", "1"])
    err = capsys.readouterr().err
    assert code == 1  # timed out: 1 s is too short for the job, and that is all
    assert "fleet run: live view on ws://127.0.0.1:" in err
