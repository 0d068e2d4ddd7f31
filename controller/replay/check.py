"""Regression replay (openpilot's process replay): a logged run's inputs through today's
controller, its commands compared with the logged ones tick by tick.

The inputs are what the controller node took in: pose measurements (robots and object), e-stops,
robot events, and the clock. Today's ``ControllerNode`` (the real sample → estimate → plan →
safety → publish pipeline, on an in-memory bus) runs the mission the log's config and mode name,
and each tick's commands are compared with the logged commands of that tick within
``tolerance`` (m/s, rad/s, any component). Open loop: the logged inputs are fed whatever the
replayed commands are, so the first divergence is the one to read.

Which inputs a tick saw:
- a dry run (lockstep, ``sim/clock`` logged): every measurement stamped up to the tick's time
  (the sim publishes a tick's measurements before its clock; the next ones are stamped at least
  one physics step later), checked against the count the clock message announces;
- a lab log (the daemon's wall clock): the measurements received before the tick's time, by the
  recorder's receive stamps (the recorder listens on the daemon's own session). Ticks are the
  command stamps; the daemon's last all-zero stop command is not a tick. Robot presence
  (liveliness) is not logged: every robot is taken as present.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller import wire
from controller.config import ConfigError, FleetConfig, InputError, parse_config
from controller.estimation.fleet import FleetEstimator
from controller.io.recorder import drop_none, read_log, read_metadata
from controller.mission.factory import build_mission
from controller.mission.planners import DeferredPlanners
from controller.replay.membus import MemoryBus
from controller.runtime.node import ControllerNode

DEFAULT_TOLERANCE = 1e-6  # m/s and rad/s: the same code on the same inputs agrees to rounding
MEASUREMENTS = ("robot_pose", "object_pose")
EVENTS = ("estop", "robot_event")


@dataclass(order=True)
class _Input:
    t: float  # the message's own stamp (s)
    index: int  # position in the log
    recv_ns: int = field(compare=False)  # the recorder's log time
    key: str = field(compare=False)
    msg: Any = field(compare=False)


@dataclass
class _Tick:
    step: int
    t: float
    index: int  # position in the log of its clock message (or its first command)
    measurements: int | None = None  # announced by the sim's clock (lockstep)


@dataclass
class LoggedRun:
    """The inputs and outputs of a logged run, sorted for the replay."""

    cfg: FleetConfig
    mode: str
    lockstep: bool
    ticks: list[_Tick]
    measurements: list[_Input]
    events: list[_Input]
    commands: dict[tuple[str, int], tuple[float, float, float]]


def load_logged_run(path: str | Path) -> LoggedRun:
    """Read what the replay needs from a log (a file, or a folder of segments)."""
    meta = read_metadata(path).get("fleet.config")
    if not meta:
        raise InputError(f"{path}: the log has no recorded config: nothing to replay against")
    try:
        cfg = parse_config(drop_none(json.loads(meta["config"])), meta.get("source", ""))
    except (ConfigError, ValueError, KeyError) as exc:
        raise InputError(f"{path}: the recorded config does not load: {exc}") from exc
    fleet = cfg.fleet.name
    clock: list[_Tick] = []
    meas: list[_Input] = []
    events: list[_Input] = []
    commands: dict[tuple[str, int], tuple[float, float, float]] = {}
    first_cmd: dict[int, int] = {}
    zero: dict[int, bool] = {}
    for i, rec in enumerate(read_log(path)):
        parsed = wire.parse_key(rec.topic, fleet)
        if parsed is None:
            continue
        name = parsed.topic.name
        if name not in (*MEASUREMENTS, *EVENTS, "sim_clock", "robot_cmd"):
            continue
        try:
            msg = rec.message()
        except wire.WireError:
            continue
        if name == "sim_clock":
            clock.append(_Tick(msg.step, msg.t, i, msg.measurements))
        elif name == "robot_cmd":
            k = _ns(msg.t)
            commands[(parsed.id, k)] = (msg.vx, msg.vy, msg.wz)
            first_cmd.setdefault(k, i)
            zero[k] = zero.get(k, True) and msg.vx == msg.vy == msg.wz == 0.0
        else:
            item = _Input(msg.t, i, rec.log_time_ns, rec.topic, msg)
            (meas if name in MEASUREMENTS else events).append(item)
    lockstep = bool(clock)
    if lockstep:
        ticks = sorted(clock, key=lambda k: k.step)
    else:
        stamps = sorted(first_cmd, key=lambda k: first_cmd[k])
        if stamps and zero[stamps[-1]]:
            stamps = stamps[:-1]  # the daemon's stop command at shutdown
        ticks = [_Tick(n, k / 1e9, first_cmd[k]) for n, k in enumerate(stamps)]
    meas.sort(key=(lambda m: (m.t, m.index)) if lockstep else (lambda m: (m.recv_ns, m.index)))
    events.sort(key=lambda m: m.index)
    return LoggedRun(cfg, meta.get("mode", ""), lockstep, ticks, meas, events, commands)


def _ns(t: float) -> int:
    return int(round(t * 1e9))


def mission_kind(mode: str) -> str:
    """The mission a log's mode names (``daemon/stage``: stage; a dry run: the whole job)."""
    kind = mode.split("/", 1)[1] if mode.startswith("daemon/") else "capture"
    return kind or "capture"


def check_log(
    path: str | Path,
    tolerance: float = DEFAULT_TOLERANCE,
    mission: str | None = None,
    stop_at_first: bool = True,
) -> dict[str, Any]:
    """Replay a log through today's controller (up to the first diverging tick unless
    ``stop_at_first`` is False); the ``check`` object of ``fleet replay --json``: ``ok``,
    ``ticks`` (replayed), ``logged_ticks``, ``compared`` (commands), ``missing`` (replayed
    commands with no logged one), ``max_error``, ``tolerance``, ``diverged`` (commands beyond
    it), ``first_divergence`` (``{tick, t, robot, logged, replayed, error}`` or None),
    ``input_mismatches`` (ticks whose measurement count differs from the one the sim
    announced), ``mission``, ``mode``, ``lockstep``, ``message``."""
    res, run, _bus, kind = replay(path, tolerance, mission, stop_at_first)
    return res.summary(run, kind)


def replay(
    path: str | Path,
    tolerance: float = DEFAULT_TOLERANCE,
    mission: str | None = None,
    stop_at_first: bool = True,
) -> tuple[_Result, LoggedRun, MemoryBus, str]:
    """:func:`check_log`'s replay itself: its result, the logged run, the in-memory bus with
    everything today's controller published (``bus.sent``, by key), and the mission kind."""
    run = load_logged_run(path)
    kind = mission or mission_kind(run.mode)
    bus = MemoryBus(run.cfg.fleet.name)
    # the plans after the latency the dry run modelled (the same jobs, in the same order)
    planners = DeferredPlanners.for_config(run.cfg)
    mission = build_mission(run.cfg, kind, planners=planners)
    node = ControllerNode(run.cfg, bus, mission, _estimator(run.cfg))
    for rid in run.cfg.robot_ids:
        bus.alive_cb["robot"](rid, True)  # liveliness is not logged: every robot present
    margin = 0.5 * run.cfg.sim.timestep
    res = _Result(tolerance)
    m = e = 0
    delivered = 0
    for tick in run.ticks:
        while m < len(run.measurements) and _due(run, run.measurements[m], tick, margin):
            item = run.measurements[m]
            bus.deliver_key(item.key, item.msg, item.recv_ns / 1e9)
            m += 1
            delivered += 1
        while e < len(run.events) and run.events[e].index < tick.index:
            bus.deliver_key(run.events[e].key, run.events[e].msg, run.events[e].recv_ns / 1e9)
            e += 1
        if tick.measurements is not None and tick.measurements != delivered:
            res.input_mismatches += 1
        node.tick(tick.t, step=tick.step)
        res.compare(tick, run, bus)
        if stop_at_first and res.first is not None:
            break
    return res, run, bus, kind


def _due(run: LoggedRun, item: _Input, tick: _Tick, margin: float) -> bool:
    if run.lockstep:
        return item.t <= tick.t + margin
    return item.recv_ns <= _ns(tick.t)


def _estimator(cfg: FleetConfig) -> FleetEstimator:
    """The filters as the run built them (``runtime.wiring.make_estimator``)."""
    return FleetEstimator(
        [(r.id, r.kind) for r in cfg.robots], cfg.estimation, cfg.fleet.stale_after
    )


@dataclass
class _Result:
    tolerance: float
    ticks: int = 0
    compared: int = 0
    missing: int = 0
    diverged: int = 0
    input_mismatches: int = 0
    max_error: float = 0.0
    first: dict[str, Any] | None = None
    _seen: dict[str, int] = field(default_factory=lambda: defaultdict(int))

    def compare(self, tick: _Tick, run: LoggedRun, bus: MemoryBus) -> None:
        self.ticks += 1
        for rid in run.cfg.robot_ids:
            sent = bus.sent.get(bus.key("robot_cmd", id=rid), [])
            if len(sent) <= self._seen[rid]:
                continue
            cmd = sent[-1]
            self._seen[rid] = len(sent)
            logged = run.commands.get((rid, _ns(tick.t)))
            if logged is None:
                self.missing += 1
                continue
            replayed = (cmd.vx, cmd.vy, cmd.wz)
            err = float(np.max(np.abs(np.subtract(replayed, logged))))
            self.compared += 1
            self.max_error = max(self.max_error, err)
            if err > self.tolerance or not math.isfinite(err):
                self.diverged += 1
                if self.first is None:
                    self.first = {
                        "tick": tick.step,
                        "t": tick.t,
                        "robot": rid,
                        "logged": [round(v, 6) for v in logged],
                        "replayed": [round(v, 6) for v in replayed],
                        "error": err,
                    }

    def summary(self, run: LoggedRun, kind: str) -> dict[str, Any]:
        ok = self.first is None and self.compared > 0
        if self.first is not None:
            f = self.first
            message = (
                f"first divergence at tick {f['tick']} (t={f['t']:.3f} s), robot {f['robot']}: "
                f"logged (vx, vy, wz) = {tuple(f['logged'])}, replayed {tuple(f['replayed'])} "
                f"(error {f['error']:.3g} > {self.tolerance:g}); "
                f"{self.diverged} of {self.compared} commands differ"
            )
        elif self.compared == 0:
            message = "no logged command to compare with"
        else:
            message = (
                f"{self.compared} commands over {self.ticks} ticks agree "
                f"(max error {self.max_error:.3g} <= {self.tolerance:g})"
            )
        return {
            "ok": ok,
            "mode": run.mode,
            "mission": kind,
            "lockstep": run.lockstep,
            "ticks": self.ticks,
            "logged_ticks": len(run.ticks),
            "compared": self.compared,
            "missing": self.missing,
            "diverged": self.diverged,
            "max_error": self.max_error,
            "tolerance": self.tolerance,
            "input_mismatches": self.input_mismatches,
            "first_divergence": self.first,
            "message": message,
        }
