"""Issue 31 item 4: a log that cannot be written never stops the fleet, and loses only what it
must. The daemon under ``prlimit --fsize`` (util-linux; the file-size limit makes every write
past it fail with EFBIG, as a full disk fails with ENOSPC, and root is not exempt) keeps
controlling, counts the errors (``fleet status``: ``log_errors``, ``log_dropped``), says so at
most once a second and writes a new segment when the limit is lifted; what it wrote before stays
readable, the e-stop put meanwhile is in the new segment. In-process: a segment path that cannot
be opened (a folder in its place), and the bounded queue that never drops an event."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time

import pytest

from controller import wire
from controller.io import recorder as rec_mod
from controller.io.recorder import McapRecorder, read_log, segments
from tests.support.config import ROOT
from tests.support.lab import fleet_json, lab_config, spawn, status, stop_all, tail
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

EVENT = "fleet/lab/estop"
POSE = "fleet/lab/robot/r1/pose"


class _Piped:
    """A ``fleet`` process whose output goes through a pipe (a pipe has no file-size limit:
    its log lines survive the ``prlimit`` the test puts on it), read into ``lines``."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "controller.cli", *args],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[tuple[float, str]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append((time.monotonic(), line))

    def text(self) -> str:
        return "".join(line for _, line in self.lines[:])


def _prlimit(pid: int, fsize: str) -> None:
    subprocess.run(["prlimit", "--pid", str(pid), f"--fsize={fsize}"], check=True)


def test_a_full_disk_does_not_stop_the_daemon_and_the_log_resumes(tmp_path, port):
    assert shutil.which("prlimit"), "util-linux prlimit is needed"
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    out = tmp_path / "d.mcap"
    procs = [spawn(tmp_path / "hub.txt", "hub", "--config", c)]
    daemon = _Piped("daemon", "--config", c, "--mission", "hold", "--out", str(out))
    procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")]
    try:
        wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
        code, res = fleet_json("resume", "--config", c, "--timeout", "30")
        assert code == 0, res
        # messages on disk (a size alone can be the header, its schemas and channels only)
        wait_for(lambda: out.exists() and len(list(read_log(out))) > 0, 20, "messages flushed")
        before = len(list(read_log(out)))

        # the disk is full: every write past 1 KiB fails (the latch file, ≈ 200 B, still fits)
        _prlimit(daemon.proc.pid, "1024:")
        failed_at = time.monotonic()
        wait_for(lambda: status(cfg)["counters"]["log_errors"] > 0, 20, "a write error")
        ticks = status(cfg)["counters"]["ticks"]
        code, res = fleet_json("estop", "--config", c, "--timeout", "10")
        assert code == 0 and res["daemon_confirmed"], res  # the daemon still obeys the e-stop
        wait_for(lambda: status(cfg)["counters"]["ticks"] > ticks + 40, 20, "ticks going on")
        # still failing: a new segment cannot hold its own header; every message is lost
        wait_for(lambda: status(cfg)["counters"]["log_errors"] >= 3, 20, "retries failing")
        st = status(cfg)
        assert st["ok"] and st["estop"] is True and st["counters"]["log_dropped"] > 0, st

        _prlimit(daemon.proc.pid, "unlimited:")  # space again
        healed_at = time.monotonic()
        wait_for(lambda: "writing again" in daemon.text(), 20, "the log resumed")
        said = [t for t, line in daemon.lines[:] if "recorder: cannot" in line]
        assert 1 <= len(said) <= (healed_at - failed_at) + 2, daemon.text()[-3000:]
        errors = status(cfg)["counters"]["log_errors"]
    finally:
        codes = stop_all([daemon.proc, *procs])
    assert all(code == 0 for code in codes), (
        codes,
        daemon.text()[-3000:],
        [tail(p) for p in procs],
    )
    # the first segment reads up to the failure; the e-stop put meanwhile is in the new one
    assert len(list(read_log(segments(out)[0]))) >= before
    resumed = segments(out)[1:]
    assert resumed, list(tmp_path.glob("d*.mcap"))
    estops = [r.message() for s in resumed for r in read_log(s, [EVENT])]
    assert any(m.engaged for m in estops), estops
    assert f"{errors} write errors" in daemon.text() or "LOG INCOMPLETE" in daemon.text()


def test_a_segment_that_cannot_be_opened_is_counted_and_writing_resumes(tmp_path, monkeypatch):
    monkeypatch.setattr(rec_mod, "RETRY_S", 0.05)
    path = tmp_path / "run.mcap"
    blocked = tmp_path / "run" / "run_001.mcap"
    blocked.mkdir(parents=True)  # the next segment's path is a folder: opening it fails (root too)
    rec = McapRecorder(path, "lab", flush_interval=0.05, sim_epoch=0.0, split_s=1.0)
    try:
        for i in range(10):  # 0.0 .. 0.9 s: the first segment
            rec.record(POSE, wire.PoseMeasurement(t=i * 0.1, x=i, y=0, theta=0))
        rec.record(POSE, wire.PoseMeasurement(t=1.0, x=10, y=0, theta=0))  # the roll fails
        wait_for(lambda: rec.drops()["log_errors"] >= 1, 10, "the write error counted")
        rec.record(EVENT, wire.EStop(t=1.1, engaged=True, source="op", reason="held"))
        rec.record(POSE, wire.PoseMeasurement(t=1.2, x=12, y=0, theta=0))  # lost, counted
        wait_for(lambda: rec.drops()["log_dropped"] >= 2, 10, "the lost messages counted")
        assert rec._thread.is_alive()
        blocked.rmdir()
        wait_for(lambda: len(rec.segments) == 2, 10, "a new segment")
        rec.record(POSE, wire.PoseMeasurement(t=1.5, x=15, y=0, theta=0))
    finally:
        rec.close()
    first = [r.message().x for r in read_log(tmp_path / "run" / "run_000.mcap")]
    assert first == [float(i) for i in range(10)]
    second = list(read_log(tmp_path / "run" / "run_001.mcap"))
    assert [r.topic for r in second] == [EVENT, POSE]  # the held e-stop first
    assert rec.drops()["log_dropped"] == 2 and rec.drops()["log_errors"] >= 1


def test_the_queue_drops_the_oldest_samples_never_an_event():
    q = rec_mod._Queue(maxsize=3)
    for i in range(5):
        q.put(("pose", i))
        if i == 1:
            q.put(("estop", i), keep=True)
    got = q.take(0.0)  # all at once, in the order put
    assert got == [("estop", 1), ("pose", 2), ("pose", 3), ("pose", 4)]
    assert q.dropped == 2
    assert q.qsize() == 0


def test_the_writer_takes_its_samples_in_batches_on_a_kick_and_events_at_once():
    """Samples wake nobody (the daemon's tick kicks the writer once); an event does."""
    q = rec_mod._Queue(maxsize=100)
    for i in range(3):
        q.put(("pose", i))
    waker = threading.Timer(0.05, q.kick)
    waker.start()
    t0 = time.monotonic()
    assert q.take(10.0) == [("pose", 0), ("pose", 1), ("pose", 2)]
    assert time.monotonic() - t0 < 5.0  # the kick, not the timeout
    q.put(("pose", 3))
    assert q.take(0.05) == [("pose", 3)]  # no kick: the timeout takes them
    q.put(("estop", 4), keep=True)
    t0 = time.monotonic()
    assert q.take(10.0) == [("estop", 4)]
    assert time.monotonic() - t0 < 5.0
