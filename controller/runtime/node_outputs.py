"""The controller node's outputs: one command per robot (with a time-to-live), the mission's
plan events, the filters' states, and in the lockstep dry run the ``TickDone`` answer.

Part of ``ControllerNode`` (``controller/runtime/node.py``): its publish stage calls
``publish``. Every command sent is also told to the estimator (its motion model's input).
"""

from __future__ import annotations

import numpy as np

from controller import wire
from controller.config import FleetConfig
from controller.mission.types import FleetView, MissionOutput
from controller.runtime.node_inputs import Estimator, NodeCounters, known


class NodeOutputs:
    """The node's publishers, built once per robot, and the sequence number they share."""

    def __init__(self, cfg: FleetConfig, bus, counters: NodeCounters, lossless: bool) -> None:
        self.cfg = cfg
        self.bus = bus
        self.ids = cfg.robot_ids
        self.counters = counters
        self._seq = 0
        self._cmd = {
            r: bus.publisher("robot_cmd", command=True, lossless=lossless, id=r) for r in self.ids
        }
        self._state = {r: bus.publisher("robot_state", id=r) for r in self.ids}
        self._object = bus.publisher("object_state")
        self._done = bus.publisher("sim_done", command=True, lossless=True)

    def for_handshake(self) -> list:
        """Publishers whose subscribers must be matched before the first tick."""
        return [*self._cmd.values(), self._done]

    def commands(self, now: float, cmds: np.ndarray, est: Estimator) -> None:
        """One command per robot (rows of ``cmds``: vx, vy, wz in the body frame)."""
        ttl = self.cfg.fleet.cmd_ttl
        for i, rid in enumerate(self.ids):
            vx, vy, wz = (float(v) for v in cmds[i])
            self._seq += 1
            self._cmd[rid].put(wire.Twist2D(t=now, seq=self._seq, vx=vx, vy=vy, wz=wz, ttl=ttl))
            est.command(rid, now, vx, vy, wz)
            self.counters.commands += 1

    def events(self, now: float, out: MissionOutput) -> None:
        """The mission's plan events of this tick, each on ``plan/<kind>``."""
        for ev in out.events:
            self._seq += 1
            data = ev.to_dict()
            self.bus.put(
                "plan",
                wire.PlanEvent(t=now, seq=self._seq, kind=ev.kind, phase=out.phase, data=data),
                what=ev.kind,
            )

    def done(self, now: float, step: int) -> None:
        """The lockstep's answer: this tick's commands are out."""
        self._done.put(wire.TickDone(t=now, seq=step, step=step, commands=self.counters.commands))

    def hold(self, now: float) -> None:
        """Command every robot to stop now (shutdown, mission end)."""
        for rid in self.ids:
            self._seq += 1
            self._cmd[rid].put(wire.Twist2D(t=now, seq=self._seq, ttl=self.cfg.fleet.cmd_ttl))

    def states(self, now: float, view: FleetView, est: Estimator, arrested: bool) -> None:
        """Every filter's state (robots, object) at the tick."""
        for i, rid in enumerate(self.ids):
            e = known(est.robot_estimate(rid, now))
            if e is None:
                continue
            self._state[rid].put(
                wire.RobotState(
                    t=now,
                    seq=self.counters.ticks,
                    id=rid,
                    x=e.x,
                    y=e.y,
                    theta=e.theta,
                    vx=e.vx,
                    vy=e.vy,
                    wz=e.wz,
                    sigma_xy=e.sigma_xy,
                    sigma_theta=e.sigma_theta,
                    stale=bool(view.stale[i]),
                    rejected=int(e.rejected),
                )
            )
        o = known(est.object_estimate(now))
        if o is not None:
            self._object.put(
                wire.ObjectState(
                    t=now,
                    seq=self.counters.ticks,
                    x=o.x,
                    y=o.y,
                    theta=o.theta,
                    vx=o.vx,
                    vy=o.vy,
                    wz=o.wz,
                    sigma_xy=o.sigma_xy,
                    stale=bool(o.stale),
                    arrested=arrested,
                )
            )
