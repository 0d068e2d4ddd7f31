"""The MCAP recorder: every sample lands on its key's channel with its schema; a recorder
killed with SIGKILL leaves a file that still yields every message older than about a second."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

from controller import wire
from controller.config import ZenohSection
from controller.io.bus import Bus
from controller.io.recorder import McapRecorder, read_log
from tests.support.config import ROOT, base_config_dict, deep_update, write_toml
from tests.support.wait import wait_for


def test_recorder_writes_channels_schemas_and_times(tmp_path):
    path = tmp_path / "r.mcap"
    with McapRecorder(path, "lab", flush_interval=0.1) as rec:
        rec.record("fleet/lab/robot/r1/cmd", wire.Twist2D(t=1.5, seq=1, vx=0.2), recv_time=10.0)
        rec.record("fleet/lab/object/pose", wire.PoseMeasurement(t=2.5, x=1, y=2, theta=0))
        rec.on_sample("fleet/lab/robot/r1/cmd", b"not json", 11.0)  # dropped, counted
    recs = list(read_log(path))
    assert [r.topic for r in recs] == ["fleet/lab/robot/r1/cmd", "fleet/lab/object/pose"]
    assert recs[0].schema == "fleet.Twist2D" and recs[1].schema == "fleet.PoseMeasurement"
    assert recs[0].log_time_ns == 10_000_000_000 and recs[0].publish_time_ns == 1_500_000_000
    assert recs[0].message() == wire.Twist2D(t=1.5, seq=1, vx=0.2)
    assert rec.dropped == 1
    # the finished file has a summary readable by the stock mcap reader too
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count == 2
    schema = json.loads(next(iter(summary.schemas.values())).data)
    assert schema["type"] == "object"


def test_recorder_survives_sigkill(tmp_path, port):
    ep = f"tcp/127.0.0.1:{port}"
    cfg = deep_update(base_config_dict(), {"fleet": {"name": "k"}, "log": {"flush_interval": 0.5}})
    cfg["zenoh"] = {"mode": "peer", "listen": [ep], "connect": []}
    cfg_path = write_toml(tmp_path / "k.toml", cfg)
    out = tmp_path / "kill.mcap"
    with Bus(ZenohSection(), "k", listen=[ep], connect=[]) as bus:
        pub = bus.publisher("robot_pose", id="r1")
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "controller.cli",
                "record",
                "--config",
                str(cfg_path),
                "--out",
                str(out),
            ],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
        try:
            # handshake: the recorder's subscriber matches our publisher
            wait_for(lambda: pub._pub.matching_status.matching, 20.0, "the recorder to subscribe")
            sent: list[tuple[int, float]] = []
            t_end = time.monotonic() + 3.0
            i = 0
            while time.monotonic() < t_end:
                pub.put(wire.PoseMeasurement(t=float(i), seq=i, x=0.01 * i, y=0.0, theta=0.0))
                sent.append((i, time.monotonic()))
                i += 1
                time.sleep(0.01)  # pacing the publisher, not a handshake
            killed_at = time.monotonic()
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    got = {r.message().seq for r in read_log(out)}
    old = [seq for seq, ts in sent if killed_at - ts > 1.1]
    assert len(old) > 100
    missing = sorted(set(old) - got)
    assert not missing, f"{len(missing)} messages older than 1.1 s lost, e.g. {missing[:5]}"


def test_recorder_sigterm_finishes_file(tmp_path, port):
    ep = f"tcp/127.0.0.1:{port}"
    cfg = base_config_dict()
    cfg["zenoh"] = {"mode": "peer", "listen": [ep], "connect": []}
    cfg_path = write_toml(tmp_path / "t.toml", cfg)
    out = tmp_path / "term.mcap"
    with Bus(ZenohSection(), "lab", listen=[ep], connect=[]) as bus:
        pub = bus.publisher("robot_cmd", id="r2")
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "controller.cli",
                "record",
                "--config",
                str(cfg_path),
                "--out",
                str(out),
            ],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
        try:
            wait_for(lambda: pub._pub.matching_status.matching, 20.0, "the recorder to subscribe")
            for i in range(20):
                pub.put(wire.Twist2D(t=float(i), seq=i))
            # handshake: the recorder has flushed all of them to disk (beside them: the scene)
            key = "fleet/lab/robot/r2/cmd"
            wait_for(
                lambda: sum(r.topic == key for r in read_log(out)) == 20,
                20.0,
                "the samples on disk",
            )
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=20) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    from mcap.reader import make_reader

    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()  # present only if the file was finished
    assert summary is not None
    ch = next(c.id for c in summary.channels.values() if c.topic == key)
    assert summary.statistics.channel_message_counts[ch] == 20
