"""The approach's detours around static obstacles are planned off the tick (issue 33 item 4): a
robot whose straight line to its station crosses an obstacle holds while its route is asked of
the planner port (kind ``detour``), then follows it; the tick itself never builds a roadmap nor
runs A*."""

from __future__ import annotations

import numpy as np
import pytest

from controller import geometry
from controller.mission.job import CaptureJob
from controller.mission.planners import PlanResult, run_job
from controller.mission.types import FleetView, Phase, step
from controller.planning import roadmap
from tests.support.capture_scenarios import SCENARIOS, scenario

DT = 0.05


class Queue:
    """A planner port that computes nothing until the test says so (the worker, by hand)."""

    def __init__(self) -> None:
        self.jobs: dict[int, tuple[str, object, tuple]] = {}
        self.done: dict[int, PlanResult] = {}
        self._next = 0

    def submit(self, kind, t, fn, *args):
        self._next += 1
        self.jobs[self._next] = (kind, fn, args)
        return self._next

    def poll(self, ticket, t):
        return self.done.pop(ticket, None)

    def discard(self, ticket):
        self.jobs.pop(ticket, None)

    def run(self, kind: str) -> int:
        """Compute every queued job of ``kind``; how many."""
        todo = [k for k, (kk, _, _) in self.jobs.items() if kk == kind]
        for k in todo:
            _, fn, args = self.jobs.pop(k)
            self.done[k] = run_job(fn, args)
        return len(todo)


def view(j: CaptureJob, t: float, poses: np.ndarray) -> FleetView:
    n = j.n
    return FleetView(
        t, j.cfg.robot_ids, poses, np.zeros((n, 3)), np.zeros(n, bool), np.ones(n, bool),
        np.asarray(j.cfg.object.start, float), np.zeros(3), None, False,
    )  # fmt: skip


@pytest.fixture
def no_roadmap_on_the_tick(monkeypatch):
    """Building a robot roadmap (what a detour needs) raises while this is on."""

    def refuse(*a, **k):
        raise AssertionError("the tick built a robot roadmap: a planner ran on the tick")

    monkeypatch.setattr(roadmap.RobotRoadmap, "build", staticmethod(refuse))
    return monkeypatch


def test_a_blocked_robot_holds_until_its_detour_comes_off_the_tick(no_roadmap_on_the_tick):
    poly, motion, kinds, start, obstacles = SCENARIOS["rect-obstacle"]
    cfg = scenario(poly, {**motion, "speed": 0.0}, kinds, start, obstacles)
    port = Queue()
    j = CaptureJob(cfg, planners=port)
    poses = np.array([r.start for r in cfg.robots], float)
    t = 0.0
    out = step(j, view(j, t, poses))
    assert out.phase == Phase.APPROACH
    asked = [k for k, (kind, _, _) in port.jobs.items() if kind == "detour"]
    assert len(asked) == 1, port.jobs  # one job for every blocked robot
    held = j.inner.detours.hold
    assert held is not None and held.any() and not held.all()
    # while the route is on its way: the blocked robots hold, the others approach
    for _ in range(3):
        t += DT
        out = step(j, view(j, t, poses))
        assert np.abs(out.commands[held, :2]).max() < 1e-6  # (the safety QP's rounding: µm/s)
        assert np.abs(out.commands[~held, :2]).max() > 0.01
    # the worker computes it (off the tick: the real roadmap); the next tick takes it
    no_roadmap_on_the_tick.undo()
    assert port.run("detour") == 1
    t += DT
    out = step(j, view(j, t, poses))
    assert j.inner.detours.hold is None
    routed = [i for i in np.flatnonzero(held) if j.inner.waypoints.get(int(i))]
    assert routed, "no blocked robot got a route"
    for i in routed:  # each heads for its first waypoint, not through the obstacle
        wp = j.inner.waypoints[int(i)][0]
        v = out.commands[i, :2]
        assert np.linalg.norm(v) > 0.01
        to_wp = (wp - poses[i, :2]) / np.linalg.norm(wp - poses[i, :2])
        world_v = geometry.rot(float(poses[i, 2])) @ v  # the command is in the robot's frame
        assert np.dot(world_v, to_wp) > 0.0
