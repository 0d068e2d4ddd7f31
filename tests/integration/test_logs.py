"""Logs other tools can read: sim-time stamps in dry runs, segments closed and indexed as they
go, a crash-cut log recovered into a valid indexed file, ``fleet record`` with the config."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from controller import wire
from controller.cli import main
from controller.io.recorder import SIM_EPOCH, McapRecorder, read_log, read_metadata, segments
from controller.mission.basic import GotoMission
from controller.mission.tracking import RobotLimits
from controller.replay.log import load_run, metrics_of
from controller.runtime.dry_run import DryRun
from controller.runtime.recording import open_recorder
from tests.support.config import ROOT, base_config_dict, deep_update, make_config, write_toml
from tests.support.foxglove import errors
from tests.support.wait import wait_for


def summary_of(path):
    with open(path, "rb") as f:
        return make_reader(f).get_summary()


def test_a_dry_run_is_stamped_with_sim_time_and_carries_the_scene(tmp_path):
    cfg = make_config({"sim": {"backend": "ideal", "seed": 2}})
    target = [[r.start[0] + 0.5, r.start[1]] for r in cfg.robots]
    mission = GotoMission(target, RobotLimits.from_config(cfg.robots))
    res = DryRun(cfg, mission, tmp_path / "t.mcap", max_time=2.0).run()
    recs = list(read_log(tmp_path / "t.mcap"))
    bus = [r for r in recs if not r.topic.startswith("/")]
    # both times are the message's sim time on the sim epoch (not the writer's wall clock)
    for r in bus:
        t = json.loads(r.data)["t"]
        assert r.log_time_ns == r.publish_time_ns == round((SIM_EPOCH + t) * 1e9)
    span = (max(r.log_time_ns for r in recs) - min(r.log_time_ns for r in recs)) / 1e9
    assert span == pytest.approx(res["sim_time_s"], abs=0.06)
    assert read_metadata(tmp_path / "t.mcap")["fleet.time"]["base"] == "sim"
    # the scene channels, written beside the bus's, follow the Foxglove schemas
    scene = [r for r in recs if r.topic.startswith("/")]
    assert {r.topic for r in scene} >= {"/tf", "/scene/world", "/scene/robots", "/scene/stats"}
    for r in scene:
        assert not errors(r.schema, json.loads(r.data)), r.topic
    ch = {c.topic: c for c in summary_of(tmp_path / "t.mcap").channels.values()}
    assert ch["/tf"].message_encoding == "json"


def test_the_lab_keeps_wall_time(tmp_path):
    path = tmp_path / "lab.mcap"
    with McapRecorder(path, "lab") as rec:
        rec.record("fleet/lab/robot/r1/cmd", wire.Twist2D(t=1.7e9 + 1.5), recv_time=1.7e9 + 1.6)
    (r,) = read_log(path)
    assert r.log_time_ns == int((1.7e9 + 1.6) * 1e9) and r.publish_time_ns == int(
        (1.7e9 + 1.5) * 1e9
    )
    assert "fleet.time" not in read_metadata(path)


def test_segments_are_closed_and_indexed_as_they_go(tmp_path):
    cfg = make_config({"log": {"split_s": 1.0}})
    rec = open_recorder(cfg, tmp_path / "run.mcap", "test", sim_time=True)
    key = wire.key("robot_pose", cfg.fleet.name, id="r1")
    for i in range(70):  # 3.45 s of sim time at 20 Hz
        rec.on_sample(
            key, wire.encode(wire.PoseMeasurement(t=0.05 * i, seq=i, x=1, y=2, theta=0)), 0.0
        )
    rec.close()
    assert rec.location == tmp_path / "run" and rec.location.is_dir()
    files = segments(rec.location)
    assert [f.name for f in files] == [f"run_{k:03d}.mcap" for k in range(4)]
    for f in files:  # each one finished (summary, index) and self-contained (config first)
        s = summary_of(f)
        assert s is not None and s.statistics.message_count > 0
        assert read_metadata(f)["fleet.config"]["mode"] == "test"
        schemas = {sc.name for sc in s.schemas.values()}
        assert "fleet.PoseMeasurement" in schemas
    seqs = [r.message().seq for r in read_log(rec.location) if r.topic == key]
    assert seqs == list(range(70))
    run = load_run(rec.location)
    m = metrics_of(run)
    assert m["complete"] and m["recovered"] is None and len(m["segments"]) == 4
    assert m["robots"]["r1"]["poses"] == 70


def test_a_killed_run_is_recovered_and_replayed(tmp_path, port):
    """SIGKILL a dry run that writes segments: the closed segments open with the standard mcap
    reader, the cut one does not until ``fleet log recover`` copies it, and ``fleet replay``
    reads the folder as one run and says what came from the cut file."""
    data = deep_update(
        base_config_dict(),
        {
            "sim": {"backend": "ideal", "max_time": 600.0},
            "log": {"split_s": 1.0, "flush_interval": 0.1},
        },
    )
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    cfg_path = write_toml(tmp_path / "k.toml", data)
    out = tmp_path / "kill.mcap"
    folder = tmp_path / "kill"
    cmd = [sys.executable, "-m", "controller.cli", "run", "--config", str(cfg_path)]
    proc = subprocess.Popen(
        [*cmd, "--out", str(out)],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        # until two segments are closed and the third holds flushed chunks
        def third_has_data() -> bool:
            f = folder / "kill_002.mcap"
            return f.exists() and f.stat().st_size > 20_000

        wait_for(third_has_data, 120.0, "three segments on disk")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    files = segments(folder)
    cut = files[-1]
    for f in files[:-1]:
        assert summary_of(f).statistics.message_count > 0
    with pytest.raises(McapError), open(cut, "rb") as f:
        make_reader(f).get_summary()  # no footer: the standard reader gives up
    fixed = tmp_path / "fixed.mcap"
    assert main(["log", "recover", str(cut), str(fixed), "--json"]) == 0
    with open(fixed, "rb") as f:
        reader = make_reader(f)
        s = reader.get_summary()
        n = sum(1 for _ in reader.iter_messages())
    assert s is not None and n == s.statistics.message_count > 0
    assert n == sum(1 for _ in read_log(cut))  # every message before the cut
    assert read_metadata(fixed)["fleet.config"]["mode"] == "run/ideal"
    # the folder replays as one run, saying what came from the cut file
    r = metrics_of(load_run(folder))
    assert not r["complete"] and len(r["segments"]) == len(files)
    assert r["recovered"]["files"] == [str(cut)] and r["recovered"]["messages"] > 0
    assert r["config_recorded"] and all(m["poses"] > 0 for m in r["robots"].values())


def test_fleet_record_writes_the_config(tmp_path, port):
    from controller.config import ZenohSection
    from controller.io.bus import Bus

    ep = f"tcp/127.0.0.1:{port}"
    data = base_config_dict()
    data["zenoh"] = {"mode": "peer", "listen": [ep], "connect": []}
    cfg_path = write_toml(tmp_path / "r.toml", data)
    out = tmp_path / "rec.mcap"
    with Bus(ZenohSection(), "lab", listen=[ep], connect=[]) as bus:
        pubs = {r: bus.publisher("robot_state", id=r) for r in ("r1", "r2")}
        proc = subprocess.Popen(
            [sys.executable, "-m", "controller.cli", "record", "--config", str(cfg_path)]
            + ["--out", str(out)],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
        try:
            wait_for(lambda: all(p.matching() for p in pubs.values()), 20.0, "the recorder")
            for i in range(20):
                for k, (rid, p) in enumerate(pubs.items()):
                    p.put(
                        wire.RobotState(t=1.7e9 + 0.05 * i, id=rid, x=1.0 + 0.3 * k, y=1.0, theta=0)
                    )
            wait_for(
                lambda: sum(not r.topic.startswith("/") for r in read_log(out)) == 40,
                20.0,
                "the samples on disk",
            )
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=20) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    r = metrics_of(load_run(out))
    assert r["config_recorded"] and r["mode"] == "record"
    # the robots' sizes are known: the clearance of the two estimates, 0.3 m apart
    assert r["min_clearance_m"] == pytest.approx(0.3 - 2 * 0.1, abs=1e-6)
