"""CaptureMission: approach a moving object, close in on the capture points, arrest it (§3).

Pure per-tick mission in the node's two stages. ``plan(view) -> Intent`` is a fixed, named
sequence: the object pose the goals ride on, the goals (capture points, envelope images,
contact targets), detours around static obstacles (planned once), the targets and feed-forward
of the current phase, the projective planner (Sharma Table I), then the phase logic
(:func:`capture_phase`, a pure function). ``safety(view, intent)`` is the shared
:class:`controller.mission.guard.SafetyStage`.

Phases: ``approach`` (chase each point's image on the convex envelope, then keep station there)
-> ``close_in`` (all robots on the envelope: every one moves to its contact point,
point + (r + gap)·n) -> ``arrested`` (every robot within ``contact_tolerance`` of its contact
point; the arrest event carries the arrival spread) -> ``done`` after a short settle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission.guard import SafetyStage
from controller.mission.types import Event, FleetView, Intent, MissionOutput, Phase, Reason
from controller.planning.approach import (
    STATION_GAP,
    PlannerParams,
    envelope,
    plan_velocities,
    ray_first_hit,
    ray_to_convex,
    separate_stations,
)


@dataclass(frozen=True)
class CaptureSettings:
    """The capture mission's tuning constants, in one place (SI units).

    ``contact_gap``: gap (m) between a robot's disc and the surface at its contact target;
    ``settle_s``: how long (s) the arrested fleet stays still before the mission is done;
    ``waypoint_reached``: distance (m) at which a detour waypoint counts as reached;
    ``detour_clearance``: extra clearance (m) beyond the robot radius when testing whether the
    straight line to a station crosses an obstacle; ``detour_samples``: points tested on it;
    ``detour_spacing``: spacing (m) of a detour's waypoints. The ``[approach]`` section gives
    the tolerances, the timeout and the planner's parameters.
    """

    contact_gap: float = 0.015
    settle_s: float = 0.5
    waypoint_reached: float = 0.15
    detour_clearance: float = 0.05
    detour_samples: int = 50
    detour_spacing: float = 0.6
    envelope_tolerance: float = 0.08
    contact_tolerance: float = 0.03
    timeout: float = 180.0

    @classmethod
    def from_config(cls, cfg: FleetConfig) -> CaptureSettings:
        ap = cfg.approach
        return cls(
            envelope_tolerance=ap.envelope_tolerance,
            contact_tolerance=ap.contact_tolerance,
            timeout=ap.timeout,
        )


@dataclass(frozen=True)
class Goals:
    """World-frame goals of the capture points at one object pose, (M, 2) each."""

    points: np.ndarray
    normals: np.ndarray
    images: np.ndarray  # stations on the convex envelope (approach)
    contacts: np.ndarray  # disc centres touching the object (close in)


@dataclass(frozen=True)
class PhaseStep:
    """What :func:`capture_phase` decided this tick."""

    phase: str
    events: list[Event]
    contact_t: np.ndarray
    arrest_t: float | None
    arrival_spread: float | None
    arrest: bool = False
    done: bool = False
    failed: bool = False
    reason: str = ""


def capture_phase(
    phase: str,
    t: float,
    t0: float,
    dist: np.ndarray,
    detouring: bool,
    contact_t: np.ndarray,
    arrest_t: float | None,
    arrival_spread: float | None,
    s: CaptureSettings,
) -> PhaseStep:
    """The capture's phase logic, pure: given the distances (M,) of the assigned robots to
    their current targets at time ``t`` (s), the next phase and its events."""
    events: list[Event] = []
    contact_t = contact_t.copy()
    arrest = done = failed = False
    reason = ""

    def go(p: str) -> str:
        events.append(("phase", {"phase": p, "t": t}))
        return p

    if phase == Phase.APPROACH and np.all(dist < s.envelope_tolerance) and not detouring:
        phase = go(Phase.CLOSE_IN)
    elif phase == Phase.CLOSE_IN:
        arrived = dist < s.contact_tolerance
        contact_t[arrived & np.isnan(contact_t)] = t
        if np.all(arrived):
            arrest_t = t
            arrival_spread = float(np.nanmax(contact_t) - np.nanmin(contact_t))
            phase = go(Phase.ARRESTED)
            arrest = True
            events.append(("arrest", {"t": t, "arrival_spread_s": arrival_spread}))
    elif phase == Phase.ARRESTED and arrest_t is not None and t - arrest_t >= s.settle_s:
        phase = go(Phase.DONE)
    done = phase == Phase.DONE  # stays done (a reader may miss one tick)
    if phase in (Phase.APPROACH, Phase.CLOSE_IN) and t - t0 > s.timeout:
        phase = go(Phase.FAILED)
        failed, reason = True, Reason.TIMEOUT
    return PhaseStep(
        phase, events, contact_t, arrest_t, arrival_spread, arrest, done, failed, reason
    )


@dataclass
class CaptureMission:
    """Approach and arrest. ``points``/``normals`` (M, 2) in the object frame; ``assignment``
    (M,) robot index per point. Robots without a point stay still (the filter still moves them
    out of harm's way)."""

    points: np.ndarray
    normals: np.ndarray
    assignment: np.ndarray
    cfg: FleetConfig
    rng: np.random.Generator
    settings: CaptureSettings | None = None
    phase: str = Phase.APPROACH
    guard: SafetyStage | None = None
    waypoints: dict[int, list[np.ndarray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cfg = self.cfg
        ap = cfg.approach
        self.s = self.settings or CaptureSettings.from_config(cfg)
        self.points = np.asarray(self.points, float)
        nrm = np.asarray(self.normals, float)
        self.normals = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        self.assignment = np.asarray(self.assignment, int)
        self.guard = self.guard or SafetyStage(cfg)
        self.n = len(cfg.robots)
        self.radii = self.guard.radii
        self.max_speed = self.guard.limits.max_speed
        self.dt = 1.0 / cfg.fleet.rate_hz
        self.obstacles = self.guard.obstacles
        self.object_poly = self.guard.object_poly
        self.params = PlannerParams(
            max_turn=np.deg2rad(ap.max_turn_deg),
            projection=ap.projection,
            alpha=np.deg2rad(ap.alpha_deg),
            alpha_growth=ap.alpha_growth,
            alpha_max=np.deg2rad(ap.alpha_max_deg),
        )
        self.assigned = np.zeros(self.n, bool)
        self.assigned[self.assignment] = True
        self.t0: float | None = None
        self.heading: np.ndarray | None = None
        self.contact_t = np.full(len(self.points), np.nan)
        self.arrest_t: float | None = None
        self.arrival_spread: float | None = None
        self._detours_planned = False

    # --- stage 1: the pose the goals ride on ------------------------------------------------
    def goal_pose(self, view: FleetView) -> np.ndarray:
        """The object's next pose (one tick ahead): a longer look-ahead would put the trailing
        robots' contact points inside the object as it is now."""
        if view.object_velocity is not None:
            return np.asarray(view.object_pose, float) + np.asarray(view.object_velocity) * self.dt
        if view.object_prediction is not None:
            return np.asarray(view.object_prediction, float)
        return np.asarray(view.object_pose, float)

    # --- stage 2: the goals -------------------------------------------------------------------
    def goals(self, pose: np.ndarray) -> Goals:
        """World capture points, normals, envelope images and contact targets (M, 2 each)."""
        pts = geometry.transform(self.points, pose)
        nrm = self.normals @ geometry.rot(float(pose[2])).T
        world = geometry.transform(self.object_poly, pose)
        img = ray_to_convex(pts, nrm, envelope(world, self.cfg.approach.envelope_margin))
        r = self.radii[self.assignment]
        contact = pts + (r + self.s.contact_gap)[:, None] * nrm
        # a ray out of a deep notch crosses the object's own arm before it leaves the hull:
        # keep the image on the free part of the ray (the robot waits inside the notch)
        free = ray_first_hit(pts, nrm, world) - r - STATION_GAP
        out = np.minimum(np.sum((img - pts) * nrm, axis=1), free)
        out = separate_stations(pts, nrm, out, r, self.s.contact_gap)
        return Goals(pts, nrm, pts + nrm * out[:, None], contact)

    # --- stage 3: detours around static obstacles (once) ----------------------------------
    def plan_detours(self, centers: np.ndarray, images: np.ndarray) -> None:
        """Robot routes (A*) for robots whose straight line to their station is blocked."""
        from controller.planning.roadmap import RobotRoadmap

        self._detours_planned = True
        blocked = []
        for m, i in enumerate(self.assignment):
            r = self.radii[i] + self.s.detour_clearance
            grown = [envelope(p, r, 8) for p in self.obstacles]
            seg = np.linspace(centers[i], images[m], self.s.detour_samples)
            if any(geometry.points_in_polygon(seg, g).any() for g in grown):
                blocked.append((m, i))
        if not blocked:
            return
        rr = float(self.radii.max()) + self.cfg.approach.safety_margin + self.s.detour_clearance
        rm = RobotRoadmap.build(
            self.cfg.bounds_array(), self.obstacles, rr, self.cfg.route.resolution
        )
        for m, i in blocked:
            res = rm.plan(centers[i], images[m], subgoal_spacing=self.s.detour_spacing)
            if res.ok:
                self.waypoints[i] = [w[:2] for w in res.subgoals[:-1]]

    # --- stage 4: targets and feed-forward of the phase --------------------------------------
    def targets(
        self, view: FleetView, pose: np.ndarray, goals: Goals
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Goal positions (N, 2), goal velocities (N, 2) and the assigned robots' current
        targets (M, 2): stations while approaching, contacts after; detour waypoints first."""
        centers = view.poses[:, :2]
        a = self.assignment
        tgt = goals.images if self.phase == Phase.APPROACH else goals.contacts
        goal = centers.copy()
        gvel = np.zeros((self.n, 2))
        ovel = np.zeros(3) if view.object_velocity is None else np.asarray(view.object_velocity)
        goal[a] = tgt
        rel = tgt - pose[:2]
        gvel[a] = ovel[:2] + ovel[2] * np.stack([-rel[:, 1], rel[:, 0]], 1)
        for i, wps in list(self.waypoints.items()):
            while wps and np.linalg.norm(centers[i] - wps[0]) < self.s.waypoint_reached:
                wps.pop(0)
            if wps:
                goal[i] = wps[0]
                gvel[i] = 0.0
            else:
                del self.waypoints[i]
        return goal, gvel, tgt

    # --- stage 5: the projective planner ----------------------------------------------------
    def projective(
        self, view: FleetView, goal: np.ndarray, gvel: np.ndarray, pose: np.ndarray
    ) -> np.ndarray:
        """Sharma Table I velocities (N, 2): robots closing in may reach the object."""
        polys = self.obstacles + [geometry.transform(self.object_poly, pose)]
        avoid = np.ones((self.n, len(polys)), bool)
        if self.phase != Phase.APPROACH:
            avoid[self.assignment, -1] = False
        active = self.assigned & ~view.stale & view.present
        if self.phase == Phase.ARRESTED:
            active[:] = False
        if self.heading is None:
            th = view.poses[:, 2]
            self.heading = np.stack([np.cos(th), np.sin(th)], 1)
        vel, self.heading, _ = plan_velocities(
            view.poses[:, :2],
            self.heading,
            self.radii,
            self.max_speed,
            goal,
            gvel,
            polys,
            avoid,
            active,
            self.params,
            self.rng,
        )
        if self.phase == Phase.ARRESTED:
            vel[self.assignment] = 0.0
        return vel

    # --- the two stages the node runs ---------------------------------------------------------
    def plan(self, view: FleetView) -> Intent:
        zero = np.zeros((self.n, 2))
        if view.object_pose is None or view.estop:
            return Intent(zero, self.phase, stop=True)
        events: list[Event] = []
        if self.t0 is None:
            self.t0 = view.t
            events.append(("phase", {"phase": self.phase, "t": view.t}))
        holding = self.phase == Phase.ARRESTED  # the fleet stays still once arrested
        pose = self.goal_pose(view)
        goals = self.goals(pose)
        if not self._detours_planned:
            self.plan_detours(view.poses[:, :2], goals.images)
        goal, gvel, tgt = self.targets(view, pose, goals)
        vel = self.projective(view, goal, gvel, pose)
        dist = np.linalg.norm(view.poses[self.assignment, :2] - tgt, axis=1)
        step = capture_phase(
            self.phase,
            view.t,
            self.t0,
            dist,
            bool(self.waypoints),
            self.contact_t,
            self.arrest_t,
            self.arrival_spread,
            self.s,
        )
        if step.arrest:
            contacts = [
                {"robot": view.ids[i], "point": [float(x) for x in p]}
                for i, p in zip(self.assignment, goals.points, strict=True)
            ]
            for kind, data in step.events:
                if kind == "arrest":
                    data["contacts"] = contacts
        self.phase = step.phase
        self.contact_t, self.arrest_t = step.contact_t, step.arrest_t
        self.arrival_spread = step.arrival_spread
        hold = np.ones(self.n, bool) if holding else None
        return Intent(
            vel,
            self.phase,
            events + step.events,
            object_pose=pose,
            touch=self.assigned if self.phase != Phase.APPROACH else None,
            hold=hold,
            done=step.done,
            failed=step.failed,
            reason=step.reason,
            arrest=step.arrest,
        )

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        assert self.guard is not None
        return self.guard.apply(view, intent)

    def summary(self) -> dict[str, Any]:
        assert self.guard is not None
        return {
            "phase": str(self.phase),
            "arrival_spread_s": self.arrival_spread,
            "arrest_time_s": self.arrest_t,
            "infeasible_filter_calls": self.guard.counters.infeasible,
        }
