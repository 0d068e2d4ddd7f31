"""`fleet replay`: metrics that agree with the run, crash-cut logs, bad messages, republishing."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from controller import geometry, wire
from controller.cli import main
from controller.io.bus import Bus
from controller.io.recorder import McapRecorder, read_metadata
from controller.mission.basic import GotoMission
from controller.mission.tracking import RobotLimits
from controller.replay.log import load_run, metrics_of
from controller.replay.metrics import (
    Track,
    min_clearance,
    object_clearance,
    object_penetration,
    track_clearance,
    tracking_error,
)
from controller.replay.republish import pacing, republish
from controller.runtime.dry_run import DryRun
from controller.viz import plot_run
from tests.support.config import make_config


@pytest.fixture(scope="module")
def dry_run_log(tmp_path_factory):
    """A short ideal dry run whose robots converge on one point (so the clearance is tested)."""
    # flush often: a crash-cut copy of this short run must still hold many chunks
    cfg = make_config({"sim": {"backend": "ideal", "seed": 5}, "log": {"flush_interval": 0.02}})
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    target = np.array(cfg.robots[0].start[:2]) + [1.0, 1.0]
    mission = GotoMission(
        np.tile(target, (len(cfg.robots), 1)), RobotLimits.from_config(cfg.robots)
    )
    summary = DryRun(cfg, mission, path, max_time=4.0).run()
    return cfg, path, summary


def test_replay_agrees_with_the_run(dry_run_log, capsys):
    cfg, path, summary = dry_run_log
    assert main(["replay", str(path), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["complete"] is True and r["config_recorded"] is True and r["mode"] == "run/ideal"
    assert r["undecodable"] == 0 and r["messages"] == summary["messages_logged"]
    assert set(r["robots"]) == set(cfg.robot_ids)
    for m in r["robots"].values():
        assert m["commands"] == summary["ticks"]
        assert m["command_rate_hz"] == pytest.approx(cfg.fleet.rate_hz, rel=0.02)
        assert m["pose_rate_hz"] == pytest.approx(cfg.sim.pose_rate_hz, rel=0.05)
        # ideal sensors with 1 cm noise: the filter is better than a raw measurement
        assert m["estimate_error"]["rmse_m"] < m["measurement_error"]["rmse_m"]
        assert m["path_length_m"] > 0.1
    # robots driven to one point collide; the replay sees the overlap the run measured (truth is
    # logged at the start of each tick, the run also checks the state after the last step: a
    # tick at 0.4 m/s moves a robot 2 cm at most)
    assert summary["min_clearance_m"] < -0.05
    assert r["min_clearance_m"] == pytest.approx(summary["min_clearance_m"], abs=0.02)
    assert r["max_object_penetration_m"] == pytest.approx(
        summary["max_object_penetration_m"], abs=0.02
    )
    # the same verdict code judges the run and its replay: the collision is found by both
    assert [f["reason"] for f in r["verdict"]] == [f["reason"] for f in summary["verdict"]]
    assert "collision" in [f["reason"] for f in r["verdict"]] and summary["status"] == "failed"
    assert sorted(r["obstacle_contacts"]) == sorted(summary["obstacle_contacts"])


def test_replay_of_a_crash_cut_log(dry_run_log, tmp_path, capsys):
    _, path, _ = dry_run_log
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["replay", str(cut), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["complete"] is False
    assert r["config_recorded"] is True  # the config is the first record of the file
    assert 0 < r["messages"]
    assert all(m["poses"] > 0 for m in r["robots"].values())


def test_bad_messages_are_counted_not_fatal(tmp_path):
    """The recorder drops a bad payload (counted); a log written by another tool with one in it
    still replays, the bad message counted as undecodable."""
    from mcap.writer import Writer

    cfg = make_config()
    path = tmp_path / "bad.mcap"
    key = wire.key("robot_pose", cfg.fleet.name, id="r1")
    bad = b'{"t": 0.6, "seq": 6, "x": "far"}'
    with McapRecorder(path, cfg.fleet.name) as rec:
        for i in range(5):
            msg = wire.PoseMeasurement(t=0.1 * i, seq=i, x=1.0 + i, y=2.0, theta=0.0)
            rec.on_sample(key, wire.encode(msg), 0.1 * i)
        rec.on_sample(key, bad, 0.6)
    assert rec.bad_payloads == 1
    assert metrics_of(load_run(path))["undecodable"] == 0  # never written
    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("fleet.PoseMeasurement", "jsonschema", b"{}")
        cid = w.register_channel(key, "json", sid)
        for i in range(5):
            msg = wire.PoseMeasurement(t=0.1 * i, seq=i, x=1.0 + i, y=2.0, theta=0.0)
            w.add_message(cid, int(i * 1e8), wire.encode(msg), int(i * 1e8))
        w.add_message(cid, int(6e8), bad, int(6e8))
        w.finish()
    assert read_metadata(path) == {}
    r = metrics_of(load_run(other))
    assert r["undecodable"] == 1
    assert r["robots"]["r1"]["poses"] == 5
    assert r["config_recorded"] is False and r["min_clearance_m"] is None


def test_plots_are_written(dry_run_log, tmp_path):
    _, path, _ = dry_run_log
    files = plot_run(load_run(path), tmp_path / "plots")
    assert {f.name for f in files} == {"trajectories.png", "clearance.png", "estimation_error.png"}
    assert all(f.stat().st_size > 10_000 and f.read_bytes()[:4] == b"\x89PNG" for f in files)


def test_republish_waits_for_subscribers_and_loses_nothing(dry_run_log, port):
    cfg, path, _ = dry_run_log
    run = load_run(path)
    keys = sorted(k for k in run.topics if "/robot/r1/" in k)
    expected = sum(run.topics[k] for k in keys)
    got: list[str] = []
    lock = threading.Lock()
    arrived = threading.Condition(lock)

    def on_sample(key: str, payload: bytes, t: float) -> None:
        with arrived:
            got.append(key)
            arrived.notify_all()

    stats: dict = {}
    result: dict = {}
    with (
        Bus(cfg.zenoh, cfg.fleet.name, listen=[f"tcp/127.0.0.1:{port}"], connect=[]) as viewer,
        Bus(cfg.zenoh, cfg.fleet.name, listen=[], connect=[f"tcp/127.0.0.1:{port}"]) as player,
    ):
        # the player starts first; it waits for the subscriber declared after it
        th = threading.Thread(
            target=lambda: result.update(
                sent=republish(path, player, 0.0, keys, wait_matching=20.0, stats=stats)
            )
        )
        th.start()
        viewer.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), on_sample)
        th.join(timeout=60)
        with arrived:  # reliable, blocking delivery: every one arrives (bounded wait)
            arrived.wait_for(lambda: len(got) >= expected, timeout=20)
    assert result["sent"] == expected and stats["matched"] is True
    assert sorted(set(got)) == keys and len(got) == expected
    # paced on the log's own (sim) time: the span is the run's, not the writer's wall clock
    assert stats["log_span_s"] == pytest.approx(run_span(run), abs=0.06)


def run_span(run) -> float:
    ts = [t for k, v in run.stamps.items() if "/robot/r1/" in k for t in v]
    return max(ts) - min(ts)


def test_pacing_follows_the_log_time_at_speed():
    # stamps going back (a measurement stamped before the tick that carried it) are due at once
    assert pacing([0, 1_000_000_000, 500_000_000, 2_000_000_000], 2.0) == [0.0, 0.5, 0.5, 1.0]
    assert pacing([5, 9], 0.0) == [0.0, 0.0]


def test_missing_log_exits_2(tmp_path, capsys):
    assert main(["replay", str(tmp_path / "nope.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err


# -- the pure metrics on hand-made tracks


def test_tracking_error_against_truth():
    t = np.linspace(0, 1, 11)
    truth = Track(t, np.stack([t, 0 * t, 0 * t], 1))
    est = Track(t[1:-1], np.stack([t[1:-1], 0 * t[1:-1] + 0.03, 0 * t[1:-1]], 1))
    e = tracking_error(est, truth)
    assert e["rmse_m"] == pytest.approx(0.03) and e["samples"] == 9


def test_min_clearance_of_crossing_robots():
    t = np.linspace(0, 2, 201)
    a = Track(t, np.stack([t - 1, 0 * t, 0 * t], 1))
    b = Track(t, np.stack([1 - t, 0 * t + 0.5, 0 * t], 1))
    gap, when = min_clearance([a, b], [0.1, 0.2])
    assert gap == pytest.approx(0.5 - 0.3) and when == pytest.approx(1.0)


def test_object_penetration_of_a_disc_pushed_into_a_square():
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    t = np.linspace(0, 1, 11)
    obj = Track(t, np.zeros((11, 3)))
    robot = Track(t, np.stack([1.0 - 0.45 * t, 0 * t, 0 * t], 1))  # ends 0.05 m from the edge
    depth, when = object_penetration([robot], [0.1], obj, square)
    assert depth == pytest.approx(0.05) and when == pytest.approx(1.0)


def test_object_clearance_over_a_track_is_the_per_pose_clearance():
    """The whole track at once (a lab log's 9 000 poses in a fraction of a second) gives the
    per-pose polygon clearance, its minimum and when: through an obstacle, then clear."""
    ell = np.array([[0, 0], [1, 0], [1, 0.3], [0.3, 0.3], [0.3, 1], [0, 1]]) - 0.4
    obstacles = [np.array([[3.0, 3.0], [4.0, 3.0], [4.0, 4.0], [3.0, 4.0]])]
    bounds = [[-5.0, -5.0], [6.0, 6.0]]
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 10.0, 400)
    poses = np.c_[np.linspace(1.0, 5.5, 400), np.linspace(1.0, 3.5, 400), rng.uniform(-3, 3, 400)]
    per_pose = [
        geometry.polygon_clearance(geometry.transform(ell, p), obstacles, bounds) for p in poses
    ]
    assert np.allclose(track_clearance(ell, poses, obstacles, bounds), per_pose, atol=1e-12)
    d, when = object_clearance(Track(t, poses), ell, obstacles, bounds)
    k = int(np.argmin(per_pose))
    assert d == pytest.approx(per_pose[k], abs=1e-12) and when == t[k]
    assert d < 0  # the L crossed the square on the way


@pytest.mark.parametrize("name", ["capture", "transport"])
def test_replay_json_writes_exactly_the_documented_keys(name):
    """Every key ``fleet replay --json`` writes is in ``controller.replay.fields`` (the generated
    reference page), in its order, and none documented is missing (a capture without a goal
    writes no transport keys)."""
    from controller.replay import fields
    from tests.support.config import ROOT

    out = metrics_of(load_run(ROOT / "tests" / "replay" / "data" / f"{name}.mcap"))
    skip = () if name == "transport" else fields.GOAL_ONLY + fields.CARRIED_ONLY
    assert list(out) == [k for k in fields.TOP if k not in skip]
    for robot in out["robots"].values():
        assert list(robot) == list(fields.ROBOT)
    assert list(out["object"]) == list(fields.OBJECT)
