"""``DryRun`` is ``fleet run``: a stand-in world behind sim drivers, one agent per robot on the
robot-side zenoh session, the controller node on its own session, the lockstep clock between
them, and the MCAP recorder on the controller's session. Everything crosses the bus.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller import geometry, wire
from controller.config import FleetConfig
from controller.events import ArrestEvent, DeliveredEvent, FailureEvent, RouteEvent
from controller.io.bus import Bus
from controller.latch import released_at_start
from controller.mission.summary import summary_of
from controller.mission.types import Mission, Reason
from controller.runtime.lockstep import ControllerLockstep, LockstepCoordinator
from controller.runtime.node import ControllerNode
from controller.runtime.planner import PlannerWorker
from controller.runtime.recording import open_recorder
from controller.runtime.summary import (
    Checks,
    RunFailure,
    RunFigures,
    RunSummary,
    TransportFigures,
    limits_of,
)
from controller.runtime.wiring import make_estimator, make_hub, make_sim_drivers
from controller.verdict import RULES, VerdictRules, judge  # noqa: F401 (their old home)
from drivers.agent import Agent, AgentParams

log = logging.getLogger(__name__)
LOSS_AFTER = 0.5  # s a robot the plan has pushing may be off the object before it is a loss


@dataclass
class Verdict:
    """What the dry run measured against the hardware contract, accumulated over the run, with
    the sim time each figure was reached (for the failure's ``t``)."""

    min_clearance_m: float = math.inf
    max_object_penetration_m: float = 0.0
    obstacle_contacts: set[str] = field(default_factory=set)
    object_min_clearance_m: float = math.inf
    missed_ticks: int = 0
    watchdog_stops: int = 0
    clamped_commands: int = 0
    vy_dropped: int = 0
    when: dict[str, float] = field(default_factory=dict)

    def update(self, t: float, check) -> None:
        if check.min_clearance < self.min_clearance_m:
            self.min_clearance_m = check.min_clearance
            self.when["collision"] = t
        if check.object_penetration > self.max_object_penetration_m:
            self.max_object_penetration_m = check.object_penetration
            self.when["penetration"] = t
        if set(check.obstacle_contacts) - self.obstacle_contacts:
            self.when.setdefault("obstacle_contact", t)
        self.obstacle_contacts.update(check.obstacle_contacts)
        if check.object_clearance < self.object_min_clearance_m:
            self.object_min_clearance_m = check.object_clearance
            self.when["object_collision"] = t


class ArrestScore:
    """The arrest scored from ground truth: each contact robot's true gap to the object when
    the arrest is declared, and how far the object (any vertex) moves from the start of the
    hold that led to it until transport begins."""

    AFTER = {"route", "rearrange", "transport"}  # phases after which the object is carried

    def __init__(self, cfg: FleetConfig) -> None:
        self.poly = geometry.ensure_ccw(cfg.object_polygon())
        self.radius = {r.id: r.radius for r in cfg.robots}
        self.hold_start: np.ndarray | None = None
        self.phase = ""
        self.gaps: dict[str, float] | None = None
        self.displacement: float | None = None
        self.arrest_t: float | None = None
        self.carried = False
        self.phases: list[dict[str, Any]] = []  # each phase entered, with its sim time

    def tick(self, t: float, out, world) -> None:
        if out is None:
            return
        poly = geometry.transform(self.poly, world.object_pose())
        if out.phase != self.phase:
            self.phases.append({"phase": str(out.phase), "t": round(t, 3)})
        if out.phase == "hold" and self.phase != "hold":
            self.hold_start, self.displacement = poly, 0.0  # a new hold (after an escape too)
        self.carried |= out.phase in self.AFTER
        if self.hold_start is not None and not self.carried:
            moved = float(np.max(np.linalg.norm(poly - self.hold_start, axis=1)))
            self.displacement = max(self.displacement or 0.0, moved)
        for ev in out.events:
            if isinstance(ev, ArrestEvent) and self.arrest_t is None:
                self.arrest_t = t
                robots = ev.contact_robots
                self.gaps = {
                    rid: float(
                        geometry.polygon_signed_distance(world.robot_pose(rid)[None, :2], poly)[0]
                        - self.radius[rid]
                    )
                    for rid in robots
                }
        self.phase = out.phase


class TransportScore:
    """The transport scored from ground truth: time, path, deviation from the planned route,
    true contact forces (the world's solver), clearance to obstacles, the error at the goal."""

    PHASES = ("route", "rearrange", "transport")

    def __init__(self, cfg: FleetConfig) -> None:
        self.cfg = cfg
        self.poly = geometry.ensure_ccw(cfg.object_polygon())
        self.centroid = geometry.centroid(self.poly)
        self.start_t: float | None = None
        self.end_t: float | None = None
        self.route: np.ndarray | None = None
        self.route_length: float | None = None
        self.path: list[np.ndarray] = []  # the object's centroid, world frame, every tick
        self.path_t: list[float] = []
        self.lateral: list[float] = []
        self.forces: list[float] = []
        self.impulse = 0.0
        self.clearance = math.inf
        self.delivered = False
        # the robots the plan has pushing, against their true contacts: robot-ticks pushing,
        # those touching, contacts lost while pushing (off LOSS_AFTER s), since when each is off
        self.ids = [r.id for r in cfg.robots]
        self.push_ticks = 0
        self.push_touching = 0
        self.contact_losses = 0
        self.off_since: dict[int, float] = {}
        self.lost_now: set[int] = set()

    def tick(self, t: float, dt: float, out, world) -> None:
        if out is None:
            return
        for ev in out.events:
            if isinstance(ev, RouteEvent) and self.route is None:
                self.route = np.asarray(ev.waypoints, float)[:, :2]
                self.route_length = float(ev.length_m)
            if isinstance(ev, DeliveredEvent):
                self.delivered = True
        active = out.phase in self.PHASES
        if active and self.start_t is None:
            self.start_t = t
        if self.start_t is None or (self.end_t is not None):
            return
        if out.phase in ("done", "failed"):
            self.end_t = t
        pose = world.object_pose()
        c = geometry.transform(self.centroid[None], pose)[0]
        self.path.append(c)
        self.path_t.append(t)
        if self.route is not None and len(self.route) > 1:
            origin = pose[:2]
            d, _ = geometry.point_segment_distance(origin[None], self.route[:-1], self.route[1:])
            self.lateral.append(float(d.min()))
        forces = world.contact_forces()
        self._push_contacts(t, out.progress.get("pushing", ()), forces)
        f = list(forces.values())
        self.forces += f
        self.impulse += float(sum(f)) * dt
        obstacles = self.cfg.obstacle_polygons()
        bounds = self.cfg.bounds_array() if self.cfg.world.walls else None
        self.clearance = min(
            self.clearance,
            geometry.polygon_clearance(geometry.transform(self.poly, pose), obstacles, bounds),
        )

    def _push_contacts(self, t: float, pushing, forces: dict[str, float]) -> None:
        """Score the pushers' true contacts: a robot the plan has pushing that is off the
        object for ``LOSS_AFTER`` s after touching it is a contact lost (once per loss)."""
        for i in range(len(self.ids)):
            if i not in pushing:
                self.off_since.pop(i, None)
                self.lost_now.discard(i)
                continue
            self.push_ticks += 1
            if forces.get(self.ids[i], 0.0) > 0.0:
                self.push_touching += 1
                self.off_since.pop(i, None)
                self.lost_now.discard(i)
                continue
            since = self.off_since.setdefault(i, t)
            if t - since >= LOSS_AFTER and i not in self.lost_now:
                self.lost_now.add(i)
                self.contact_losses += 1

    def figures(self, world) -> TransportFigures:
        """The ``fleet run --json`` transport fields (None where nothing was carried)."""
        goal = self.cfg.object.goal
        if goal is None or self.start_t is None:
            return TransportFigures(transported=False if goal is not None else None)
        pose = world.object_pose()
        err = float(np.linalg.norm(pose[:2] - np.asarray(goal[:2])))
        err_deg = float(np.degrees(abs(geometry.wrap_angle(pose[2] - goal[2]))))
        t = self.cfg.transport
        within = err <= t.tolerance and err_deg <= t.heading_tolerance_deg
        path = np.asarray(self.path).reshape(-1, 2)
        goal_c = geometry.transform(self.centroid[None], np.asarray(goal, float))[0]
        end_c = geometry.transform(self.centroid[None], pose)[0]
        near = np.flatnonzero(np.linalg.norm(path - goal_c, axis=1) <= t.tolerance)
        reached = round(self.path_t[near[0]] - self.start_t, 3) if near.size else None
        lat = np.asarray(self.lateral)
        f = np.asarray(self.forces)
        end = self.end_t if self.end_t is not None else None
        return TransportFigures(
            transported=bool(self.delivered and within),
            goal_error_m=err,
            goal_error_deg=err_deg,
            transport_time_s=None if end is None else round(end - self.start_t, 3),
            route_length_m=self.route_length,
            object_path_length_m=float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            lateral_deviation_rms_m=float(np.sqrt(np.mean(lat**2))) if len(lat) else None,
            max_lateral_deviation_m=float(lat.max()) if len(lat) else None,
            contact_force_mean_n=float(f.mean()) if len(f) else None,
            contact_force_max_n=float(f.max()) if len(f) else None,
            contact_impulse_ns=self.impulse,
            transport_object_min_clearance_m=None if math.isinf(self.clearance) else self.clearance,
            goal_centroid_error_m=float(np.linalg.norm(end_c - goal_c)),
            goal_centroid_reached_s=reached,
            push_contact_share=(
                round(self.push_touching / self.push_ticks, 4) if self.push_ticks else None
            ),
            push_contact_losses=self.contact_losses,
            carried=True,
        )


def _add(a: dict[str, int], b: dict[str, int]) -> dict[str, int]:
    return {k: a.get(k, 0) + b.get(k, 0) for k in a.keys() | b.keys()}


def failure_of(
    result: Mapping[str, Any], verdict: Verdict, mission_failure: RunFailure | None
) -> RunFailure | None:
    """The run's failure, or None: the mission's own failure first, then the first verdict
    failure, then a run that never finished, then an object not delivered. ``result``: the
    ``--json`` figures and checks, with the ``verdict``."""
    if mission_failure is not None:
        return mission_failure
    if result["verdict"]:
        first = min(result["verdict"], key=lambda f: verdict.when.get(f["reason"], math.inf))
        return RunFailure(first["reason"], verdict.when.get(first["reason"]), first["detail"])
    if not result.get("done"):
        reason = Reason.ESTOP if result.get("estop") else Reason.TIMEOUT
        detail = f"sim time ran out ({result['sim_time_s']} s) in phase {result['mission_phase']}"
        return RunFailure(reason, result["sim_time_s"], detail)
    if result.get("transported") is False:
        detail = (
            f"the object ended {result.get('goal_error_m', math.nan):.2f} m and "
            f"{result.get('goal_error_deg', math.nan):.1f} deg from object.goal (truth)"
        )
        return RunFailure(Reason.NOT_DELIVERED, result["sim_time_s"], detail)
    return None


class DryRun:
    """The pybullet (or ideal) dry run of a config, end to end over zenoh."""

    progress_every = 5.0  # sim seconds between progress lines on stderr

    def __init__(
        self,
        cfg: FleetConfig,
        mission: Mission,
        out: Path,
        gui: bool = False,
        max_time: float | None = None,
        viz: bool = False,
        planners: PlannerWorker | None = None,
    ) -> None:
        """``planners``: the lockstep planner worker ``mission`` was built with (it plans off
        the tick; its plans come after their modelled latency); closed when the run ends."""
        self.cfg = cfg
        self.planners = planners
        self.viz = viz
        self.mission = mission
        self.out = out
        self.gui = gui
        self.max_time = cfg.sim.max_time if max_time is None else max_time
        self.verdict = Verdict()
        self.score = ArrestScore(cfg)
        self.carry = TransportScore(cfg)
        self.mission_failure: RunFailure | None = None
        self.run_failure: RunFailure | None = None  # the dry run itself broke (lockstep lost)
        self._next_progress = 0.0
        # a live progress display (``fleet run`` on a terminal): called every tick with sim
        # time, phase and the mission's progress figures, in place of the progress lines
        self.on_progress: Callable[[float, str, dict[str, Any]], None] | None = None

    def run(self) -> dict[str, Any]:
        """The run; its ``fleet run --json`` object (:meth:`run_summary` for the typed one)."""
        return self.run_summary().to_json()

    def run_summary(self) -> RunSummary:
        """The run, end to end; its typed summary."""
        cfg = self.cfg
        wall0 = time.monotonic()
        hub = make_hub(cfg, self.gui)
        # sim-time stamps, the Foxglove scene, segments, the live view (--viz)
        recorder = open_recorder(
            cfg, self.out, f"run/{cfg.sim.backend}", sim_time=True, viz=self.viz, who="fleet run"
        )
        try:
            with (
                Bus(cfg.zenoh, cfg.fleet.name) as ctl_bus,
                Bus(
                    cfg.zenoh,
                    cfg.fleet.name,
                    listen=[],
                    connect=list(cfg.zenoh.listen),
                    # the robots' side shares this process and the sim clock: a wall-clock
                    # stall of the machine that the lockstep rides out (sim.tick_timeout) must
                    # not cut its link either (fleet.liveliness_lease is for lab robots)
                    lease_s=max(cfg.fleet.liveliness_lease, cfg.sim.tick_timeout),
                ) as robot_bus,
            ):
                figures = self._run(hub, recorder, ctl_bus, robot_bus, wall0)
        finally:
            hub.world.close()
            recorder.close()
            if self.planners is not None:
                self.planners.close()
        return self._finish(figures, recorder, wall0)

    @classmethod
    def of(cls, cfg: FleetConfig, kind: str, out: Path, **kw: Any) -> DryRun:
        """The dry run of mission ``kind`` the way ``fleet run`` runs it: the mission built
        with a lockstep planner worker (its plans after their modelled latency)."""
        from controller.mission.factory import build_mission

        planners = PlannerWorker.for_config(cfg, lockstep=True)
        try:
            mission = build_mission(cfg, kind, planners=planners)
        except BaseException:
            planners.close()
            raise
        return cls(cfg, mission, out, planners=planners, **kw)

    def _run(self, hub, recorder, ctl_bus: Bus, robot_bus: Bus, wall0: float) -> RunFigures:
        cfg = self.cfg
        ctl_bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample)
        # a fresh world with no operator and no e-stop history: the run itself releases the
        # latch at epoch 0 (any operator's `fleet estop` on its bus still stops it)
        fresh = released_at_start("fleet run")
        node = ControllerNode(
            cfg,
            ctl_bus,
            self.mission,
            make_estimator(cfg),
            lossless_commands=True,
            extra_drops=recorder.drops,
            clock=time.perf_counter,
            latch_at_start=fresh,
        )
        drivers, emulators = make_sim_drivers(cfg, hub)
        commands_arrived = threading.Condition()
        agents = [
            Agent(
                robot_bus,
                drv,
                AgentParams(r.id, cfg.fleet.name, cfg.fleet.cmd_ttl, cfg.fleet.max_clock_skew),
                commands_arrived,
                latch_at_start=fresh,
            )
            for r, drv in zip(cfg.robots, drivers, strict=True)
        ]
        coord = LockstepCoordinator(
            robot_bus,
            hub,
            agents,
            1.0 / cfg.fleet.rate_hz,
            cfg.sim.tick_timeout,
            commands_arrived,
            planning=None if self.planners is None else lambda: self.planners.waiting,
        )
        ctl = ControllerLockstep(node, ctl_bus, wait_inputs=cfg.sim.tick_timeout)
        self._handshake(node, agents, coord)
        ctl.thread.start()
        try:
            self._loop(coord, ctl, node, hub.world, wall0)
        finally:
            node.winding_down = True  # the agents close next: their robots leave, as expected
            ctl.stop.set()
            ctl.thread.join(timeout=10)
        for a in agents:
            self.verdict.watchdog_stops += a.counters.watchdog_stops
            self.verdict.clamped_commands += a.counters.clamped
            self.verdict.vy_dropped += a.counters.vy_dropped
            a.close()
        for e in emulators:
            e.stop()
        self.verdict.missed_ticks = coord.counters.missed
        return self._summary(node, coord, ctl, hub.world, ctl_bus, robot_bus)

    def _loop(self, coord, ctl, node: ControllerNode, world, wall0: float) -> None:
        """Tick until the mission is done or failed, or sim time runs out."""
        while coord.t <= self.max_time:
            coord.tick()
            self.verdict.update(coord.t, world.check())
            if ctl.error is not None:
                raise RuntimeError("controller loop failed") from ctl.error
            if coord.lost:
                n = coord.counters.missed_in_a_row
                detail = (
                    f"the controller missed {n} ticks in a row (sim.tick_timeout "
                    f"{self.cfg.sim.tick_timeout:g} s each): its answers or its commands "
                    "stopped arriving; the run was cut short"
                )
                log.error("lockstep lost at t=%.2f s: %s", coord.t, detail)
                self.run_failure = RunFailure(Reason.LOCKSTEP_LOST, round(coord.t, 4), detail)
                break
            out = node.last_output
            self.score.tick(coord.t, out, world)
            self.carry.tick(coord.t, coord.dt, out, world)
            self._progress(coord.t, out, world)
            if out is not None and out.failed:
                self.mission_failure = _mission_failure(out, coord.t)
            if out is not None and (out.done or out.failed):
                break
            if self.cfg.sim.realtime:
                lag = coord.t - (time.monotonic() - wall0)
                if lag > 0:
                    time.sleep(lag)

    def _progress(self, t: float, out, world) -> None:
        """A progress line every few sim seconds: phase, distances, object speed (or the live
        display's update every tick)."""
        if out is not None and self.on_progress is not None:
            self.on_progress(t, str(out.phase), out.progress)
            return
        if t < self._next_progress or out is None:
            return
        self._next_progress = t + self.progress_every
        p = out.progress
        speed = float(np.hypot(*world.object_velocity()[:2]))
        extra = " ".join(f"{k} {v:.3f}" for k, v in p.items() if isinstance(v, float))
        log.info("t %6.1f s  %-9s %s  object %.2f m/s", t, out.phase, extra, speed)

    def _summary(self, node, coord, ctl, world, ctl_bus: Bus, robot_bus: Bus) -> RunFigures:
        out = node.last_output
        mission = summary_of(self.mission)
        return RunFigures(
            mission_phase=node.phase,
            done=bool(out.done) if out else False,
            failed=bool(out.failed) if out else False,
            estop=bool(node.estop),
            arrest_declared=self.score.arrest_t is not None,
            arrest_time_s=self.score.arrest_t,
            arrival_spread_s=mission.arrival_spread_s,
            contact_gaps_at_arrest_m=self.score.gaps,
            hold_displacement_m=self.score.displacement,
            phases=self.score.phases,
            object_gave_up_at_s=world.object_gave_up_at,
            sim_time_s=round(coord.t, 4),
            ticks=coord.counters.ticks,
            input_timeouts=ctl.lag_waits,
            node=dict(vars(node.counters)),
            bad_payloads=ctl_bus.stats.total + robot_bus.stats.total,
            drops=_add(node.drops(), robot_bus.drops()),
            estimator={},  # the contract's field; the filters report nothing of their own
            final_object_pose=[float(v) for v in world.object_pose()],
            rearrangements=mission.rearrangements,
            relocations=mission.relocations,
            plan_latency_s={} if self.planners is None else self.planners.summary(),
            transport=self.carry.figures(world),
            mission=mission,
            timing=node.timing_summary(),
        )

    def _finish(self, figures: RunFigures, recorder, wall0: float) -> RunSummary:
        v = self.verdict
        inf = math.isinf
        checks = Checks(
            min_clearance_m=None if inf(v.min_clearance_m) else v.min_clearance_m,
            max_object_penetration_m=v.max_object_penetration_m,
            obstacle_contacts=sorted(v.obstacle_contacts),
            object_min_clearance_m=None
            if inf(v.object_min_clearance_m)
            else v.object_min_clearance_m,
            missed_ticks=v.missed_ticks,
            watchdog_stops=v.watchdog_stops,
            clamped_commands=v.clamped_commands,
            vy_dropped=v.vy_dropped,
            wall_time_s=round(time.monotonic() - wall0, 3),
            log=str(recorder.location),
            messages_logged=recorder.written,
            **limits_of(self.cfg),
        )
        result = {**figures.to_json(), **checks.to_json()}
        result["verdict"] = judge(result)
        held = figures.hold_displacement_m
        escaped = held is not None and held > RULES.max_hold_displacement_m
        return RunSummary(
            figures,
            checks,
            result["verdict"],
            arrested=figures.arrest_declared and not escaped,
            failure=self.run_failure or failure_of(result, v, self.mission_failure),
        )

    def _handshake(self, node: ControllerNode, agents, coord, timeout: float = 20.0) -> None:
        """Wait until both sides see each other: the controller holds every robot's liveliness
        token, and every publisher on either side has a matching subscriber."""
        pubs = node.publishers_for_handshake() + coord.publishers_for_handshake()
        pubs += [a.pose_publisher for a in agents]
        deadline = time.monotonic() + timeout
        while True:
            up = int(np.count_nonzero(node.present))
            if up == len(agents) and all(p.matching() for p in pubs):
                return
            if time.monotonic() > deadline:
                unmatched = [p.key for p in pubs if not p.matching()]
                raise RuntimeError(
                    f"{up} of {len(agents)} robots came up; unmatched keys: {unmatched}"
                )
            time.sleep(0.01)


def _mission_failure(out, t: float) -> RunFailure:
    """The mission's own failure (its reason, and the detail of its ``failure`` event)."""
    detail = next((e.detail for e in out.events if isinstance(e, FailureEvent)), "")
    return RunFailure(out.reason or "failed", t, detail)
