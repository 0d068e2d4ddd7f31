"""One world per fleet, one agent per robot (issue 31 item 5): a second ``fleet world`` on a
fleet already served, or a second ``fleet driver r1`` while r1's agent is up, exits 1 naming
why, and the first one serves on untouched. A part restarted after a crash is not refused: its
predecessor's token goes with its lease."""

from __future__ import annotations

import signal
import subprocess

import pytest

from tests.support.lab import connect_client, spawn, stop_all, tail
from tests.support.wait import wait_for
from tests.support.world_lab import rehearsal_config

pytestmark = [pytest.mark.e2e]


def _ended(p: subprocess.Popen, timeout: float) -> int:
    try:
        return p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"still running: {tail(p)}") from None


def test_a_second_world_or_a_second_agent_of_one_robot_is_refused(tmp_path, port):
    c, fleet = rehearsal_config(tmp_path, port)
    c = str(c)
    world = spawn(tmp_path / "world.txt", "world", "--config", c)
    procs = [world]
    try:
        with connect_client(port, "the world", fleet_name=fleet["name"]) as bus:
            wait_for(lambda: "main" in bus.alive_ids("world", 0.5), 30, "the world's token")
            agent = spawn(tmp_path / "r1.txt", "driver", "r1", "--config", c)
            procs.append(agent)
            wait_for(lambda: "r1" in bus.alive_ids("robot", 0.5), 30, "r1's agent")

            world2 = spawn(tmp_path / "world2.txt", "world", "--config", c)
            procs.append(world2)
            assert _ended(world2, 60) == 1
            assert "another world already serves fleet" in tail(world2)

            agent2 = spawn(tmp_path / "r1-again.txt", "driver", "r1", "--config", c)
            procs.append(agent2)
            assert _ended(agent2, 60) == 1
            assert "another agent already serves robot r1" in tail(agent2)

            # the first ones serve on
            assert world.poll() is None and agent.poll() is None
            assert "r1" in bus.alive_ids("robot", 0.5) and "main" in bus.alive_ids("world", 0.5)

            # a crashed agent's successor comes up: the old token goes with its lease
            agent.send_signal(signal.SIGKILL)
            agent.wait()
            agent3 = spawn(tmp_path / "r1-restart.txt", "driver", "r1", "--config", c)
            procs.append(agent3)
            wait_for(lambda: "agent up" in tail(agent3), 30, "the restarted agent")
            assert agent3.poll() is None
    finally:
        stop_all(procs)
