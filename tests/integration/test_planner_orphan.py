"""A daemon killed with SIGKILL never shuts its planner pool down: the worker process it spawned
must end by itself (it did not: every killed daemon left a 100 MB planner process behind)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from tests.support.config import ROOT
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

CHILD = """
import os, sys, time
from controller.runtime.planner import PlannerWorker
if __name__ == "__main__":
    w = PlannerWorker({"transport": 6}, 0.05, lockstep=False, timeout=10.0)
    print(w._pool.submit(os.getpid).result(timeout=60), flush=True)
    time.sleep(600)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is gone too (reaped by init later)
    with open(f"/proc/{pid}/stat") as f:
        return f.read().split(")")[-1].split()[0] != "Z"


def test_the_planner_worker_ends_when_its_daemon_is_killed(tmp_path):
    script = tmp_path / "owner.py"
    script.write_text(CHILD)
    owner = subprocess.Popen(
        [sys.executable, str(script)],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        worker = int(owner.stdout.readline())  # the handshake: the worker answered
        assert worker != owner.pid and _alive(worker)
        owner.send_signal(signal.SIGKILL)
        owner.wait()
        wait_for(lambda: not _alive(worker), 10, "the orphaned planner worker to end")
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
