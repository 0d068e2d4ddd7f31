"""``fleet up``'s plan, checks, supervision rules and console, without the bus (the whole lab
runs in tests/integration/test_lab_up.py)."""

from __future__ import annotations

import io
import subprocess
import sys
import threading
import time

import pytest

from controller.config import ConfigError
from controller.runtime.console import PlainConsole, headline, next_step, robot_rows
from controller.runtime.lab import (
    BACKOFF_MAX,
    Lab,
    Part,
    Snapshot,
    last_warning,
    plan_parts,
    read_state,
    write_state,
)
from tests.support.config import make_config


def rehearsal(**sim):
    return make_config({"sim": {"world": "process", **sim}})


def test_the_parts_start_hub_first_then_world_agents_and_the_daemon_last(tmp_path):
    cfg = rehearsal()
    parts = plan_parts(cfg, "lab.toml", tmp_path, "capture")
    assert [p.role for p in parts] == ["hub", "world"] + ["agent"] * len(cfg.robots) + ["daemon"]
    assert [p.name for p in parts if p.role == "agent"] == list(cfg.robot_ids)
    daemon = parts[-1]
    assert daemon.argv[daemon.argv.index("--mission") + 1] == "capture"
    assert daemon.argv[daemon.argv.index("--out") + 1] == str(tmp_path / "daemon.mcap")
    assert not daemon.respawn and not parts[1].respawn  # the job's end; the world's state
    assert all(p.respawn for p in parts if p.role in ("hub", "agent"))
    # every part logs to a file of its own in the run's folder
    assert len({p.log_path for p in parts}) == len(parts)
    assert all(p.log_path.parent == tmp_path for p in parts)
    # the agents wait for the world as long as the lab does
    agent = parts[2]
    assert agent.argv[agent.argv.index("--connect-timeout") + 1] == "180"


def test_real_robots_get_no_world_unless_rehearsed(tmp_path):
    robots = [
        {
            "id": f"m{i}",
            "kind": "omni",
            "driver": "mavlink",
            "url": f"udpin:127.0.0.1:{14600 + i}",
            "profile": "px4",
            "system_id": i + 1,
            "start": [1.0 + i, 1.0, 0.0],
        }
        for i in range(3)
    ]
    cfg = make_config({"robots": robots})
    assert "world" not in [p.role for p in plan_parts(cfg, "f.toml", tmp_path, "capture")]
    parts = plan_parts(cfg, "f.toml", tmp_path, "capture", mavlink="m1")
    world = next(p for p in parts if p.role == "world")
    assert world.argv[-2:] == ["--mavlink", "m1"]


def test_remote_agents_are_waited_for_not_started_and_the_viz_reaches_the_daemon(tmp_path):
    from controller.runtime.console import part_state
    from controller.runtime.lab_launch import remote_ids

    cfg = rehearsal()
    parts = plan_parts(cfg, "lab.toml", tmp_path, "capture", remote=("r2",), viz=True)
    r2 = next(p for p in parts if p.name == "r2")
    assert r2.argv == [] and not r2.respawn
    lab = _lab(tmp_path, [r2])
    lab.start(r2)
    assert r2.proc is None and part_state(r2, time.monotonic()) == "remote, waiting"
    assert "--viz" in parts[-1].argv
    assert remote_ids(cfg, "r1, r2") == ("r1", "r2")
    with pytest.raises(ConfigError, match="--remote 'r9'"):
        remote_ids(cfg, "r9")


def test_sim_robots_without_a_shared_world_are_refused_naming_the_key():
    from controller.runtime.lab_launch import check_lab_config

    with pytest.raises(ConfigError) as err:
        check_lab_config(make_config({"sim": {"world": "solo"}}), None, None)
    assert "sim.world" in str(err.value) and "process" in str(err.value)
    check_lab_config(rehearsal(), None, None)  # the shared world: fine
    with pytest.raises(ConfigError, match="--mavlink"):
        check_lab_config(rehearsal(), "r1", None)  # r1 is no MAVLink robot


def _lab(tmp_path, parts) -> Lab:
    cfg = rehearsal()
    return Lab(cfg, parts, tmp_path, threading.Event(), lambda snap: None)


def test_a_crashed_agent_is_restarted_with_a_doubling_back_off(tmp_path):
    part = Part(
        "r1", "agent", [sys.executable, "-c", "raise SystemExit(3)"], tmp_path / "r1.log", True
    )
    lab = _lab(tmp_path, [part])
    lab.start(part)
    part.proc.wait(timeout=30)
    assert lab._reap(part) and part.exit_code == 3
    now = time.monotonic()
    lab._respawn(part, now)
    assert part.restart_at == pytest.approx(now + 1.0) and part.restarts == 0  # not yet
    lab._respawn(part, now + 0.5)
    assert part.restarts == 0
    lab._respawn(part, now + 1.0)  # due: started again
    assert part.restarts == 1 and part.restart_at is None and part.exit_code is None
    part.proc.wait(timeout=30)
    assert lab._reap(part)
    lab._respawn(part, time.monotonic())
    assert part.restart_at - time.monotonic() == pytest.approx(2.0, abs=0.5)  # doubled
    part.backoff = 1e6
    part.restart_at = None
    lab._respawn(part, time.monotonic())
    assert part.backoff == BACKOFF_MAX


def test_the_lab_fails_clearly_when_a_part_that_may_not_restart_dies_starting(tmp_path):
    world = Part(
        "world", "world", [sys.executable, "-c", "raise SystemExit(2)"], tmp_path / "w.log", False
    )
    lab = _lab(tmp_path, [world])
    lab.ready_timeout = 30
    assert lab.bring_up() is False
    assert lab.failure == "world exited (code 2) while starting"


def test_the_state_file_is_replaced_whole(tmp_path):
    path = tmp_path / "lab.json"
    write_state(path, {"pid": 1, "stage": "waiting"})
    write_state(path, {"pid": 1, "stage": "running"})
    assert read_state(path) == {"pid": 1, "stage": "running"}
    assert not list(tmp_path.glob("*.tmp"))
    assert read_state(tmp_path / "none.json") is None


def test_last_warning_is_the_message_of_the_last_warning_or_error_line(tmp_path):
    log = tmp_path / "r1.log"
    log.write_text(
        "2026-01-01 10:00:00,000 INFO drivers.agent: up\n"
        "2026-01-01 10:00:01,000 WARNING drivers.agent: robot r1: link lost\n"
        "2026-01-01 10:00:02,000 INFO drivers.agent: fine\n"
    )
    assert last_warning(log) == "robot r1: link lost"
    assert last_warning(tmp_path / "missing.log") == ""


def _snap(stage: str, estop: str = "unknown", **kw) -> Snapshot:
    return Snapshot(t=12.0, stage=stage, estop=estop, **kw)


def test_the_next_step_tells_the_operator_what_to_do():
    assert "waiting for r3" in next_step(_snap("starting", waiting_for="r3"), "lab.toml")
    fresh = next_step(_snap("waiting"), "lab.toml")
    assert "resume" in fresh and "fleet resume --config lab.toml" in fresh and "press r" in fresh
    estopped = next_step(_snap("running", "engaged"), "lab.toml")
    assert "fleet resume --config lab.toml" in estopped
    running = next_step(_snap("running", "released"), "lab.toml")
    assert "fleet estop --config lab.toml" in running and "press e" in running


def test_the_headline_and_rows_show_phase_estop_robots_and_the_way_to_go(tmp_path):
    from controller import wire

    status = wire.FleetStatus(
        t=0.0,
        seq=1,
        fleet="lab",
        phase="transport",
        robots=[{"id": "r1", "present": True, "link_lost": False}],
    )
    parts = [Part("r1", "agent", ["fleet"], tmp_path / "r1.log", True)]
    parts[0].proc = subprocess.Popen([sys.executable, "-c", "pass"])
    parts[0].proc.wait()
    parts[0].ready = True
    snap = _snap(
        "running",
        "released",
        status=status,
        parts=parts,
        latches={"robot/r1": "released"},
        cmd_hz={"r1": 20.0},
        goal_distance=1.234,
        eta_s=40.0,
        job_t=30.0,
    )
    line = headline(snap)
    assert "phase transport" in line and "released" in line
    assert "1.23 m from its goal" in line and "ETA 40 s" in line
    (row,) = robot_rows(snap, time.monotonic())
    assert row[:6] == ["r1", "ready", "present", "ok", "released", "20"]


def test_the_plain_console_prints_changes_only():
    out = io.StringIO()
    console = PlainConsole("lab.toml", out)
    console(_snap("waiting"))
    first = out.getvalue()
    assert "stage: waiting" in first and "fleet resume --config lab.toml" in first
    console(_snap("waiting"))
    assert out.getvalue() == first  # nothing changed: nothing printed
    console(_snap("running", "released"))
    assert "stage: running" in out.getvalue()[len(first) :]


def test_agents_are_a_process_each_for_a_small_fleet_and_grouped_for_a_large_one(tmp_path):
    from controller.runtime.lab_launch import GROUP, ISOLATE_UP_TO, agents_per_process

    assert agents_per_process(6, None) == 1
    assert agents_per_process(ISOLATE_UP_TO + 1, None) == GROUP
    assert agents_per_process(50, 3) == 3  # the operator's choice stands
    parts = plan_parts(rehearsal(), "lab.toml", tmp_path, "capture", agents_per_process=4)
    groups = [p for p in parts if p.role == "agent"]
    assert [p.robots for p in groups] == [("r1", "r2", "r3", "r4"), ("r5", "r6")]
    assert groups[0].argv[groups[0].argv.index("driver") + 1] == "r1,r2,r3,r4"


def test_the_run_progress_bar_shows_phase_sim_time_and_the_way_to_the_goal():
    import logging

    from controller.runtime.console import RunProgress

    root = logging.getLogger()
    levels = [h.level for h in root.handlers]
    bar = RunProgress(100.0)
    try:
        bar.update(4.0, "transport", {"to_goal_m": 2.0})
        bar.update(9.0, "transport", {"to_goal_m": 1.5})  # 0.1 m/s: 15 s of sim to go
        task = bar.progress.tasks[0]
        assert task.completed == 9.0 and task.total == 100.0
        assert task.fields["phase"] == "transport"
        assert task.fields["goal"] == "object 1.50 m from its goal, ETA 15 s of sim"
    finally:
        bar.close()
    assert [h.level for h in root.handlers] == levels  # the log as it was


def test_fleet_down_stops_the_parts_of_a_lab_whose_supervisor_died(tmp_path, capsys):
    """A supervisor killed with SIGKILL leaves its parts running in their own sessions:
    ``fleet down`` stops them (only processes that are still ``fleet`` processes)."""
    from controller.cli import main
    from controller.runtime.lab import state_path

    cfg = make_config({"log": {"dir": str(tmp_path / "runs")}})
    (tmp_path / "runs").mkdir()
    part = subprocess.Popen(
        [sys.executable, "-c", "import controller.cli, time; time.sleep(60)"], cwd=tmp_path
    )
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead = subprocess.Popen([sys.executable, "-c", "pass"])
        dead.wait()
        write_state(
            state_path(cfg),
            {"pid": dead.pid, "stage": "running", "run_dir": str(tmp_path),
             "parts": {"r1": {"pid": part.pid}, "hub": {"pid": other.pid}}},
        )  # fmt: skip
        config = tmp_path / "lab.toml"
        from tests.support.config import base_config_dict, write_toml

        data = base_config_dict()
        data["log"] = {"dir": str(tmp_path / "runs")}
        write_toml(config, data)
        # the part's command line names controller.cli only through its -c text: good enough
        assert main(["down", "--config", str(config)]) == 1  # no verdict: stopped
        assert part.wait(timeout=30) != 0  # terminated
        assert other.poll() is None  # not a fleet process: left alone
        assert "stopped its 1 processes (r1)" in capsys.readouterr().err
    finally:
        for p in (part, other):
            p.kill()
            p.wait()
