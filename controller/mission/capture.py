"""CaptureMission: approach a moving object, close in to contact, hold it, arrest it (§3).

Pure, per tick. ``plan(view) -> Intent``: the object pose the goals ride on, the goals, detours
around obstacles (planned once), the phase's targets, the projective planner (Sharma Table I),
then the phase logic (:func:`advance`); ``safety``: the shared ``SafetyStage``.

Phases:

- ``approach``: every assigned robot chases its point's station on the convex envelope, aimed
  where the object will be when the robot can get there (interception at full speed), then
  keeps station;
- ``close_in``: all robots on the envelope; each moves in to contact with its point, riding on
  the object's estimated motion until it touches; a robot that touches stops chasing and holds
  its contact target still in the world (chasing the estimated velocity of an object you push
  runs away: each push moves it, which moves the estimate, which moves the robots), and picks
  up the chase again if the object leaves it;
- ``hold``: every robot touches the object (its estimated gap below ``contact_tolerance``):
  the contact targets freeze in the world where the object is (a cage), each
  ``preload_depth`` inside the surface, and the robots hold them with no feed-forward, while
  the live object still tries to move. A held robot's motor resists up to its ``max_force``;
  one that cannot reach its target (the object is there) pushes the small preload; the cage
  does not follow the object (see ``close_in``). A robot that loses contact, or an object that
  moves more than ``hold_tolerance`` (any vertex of its estimate), sends the fleet back to
  ``close_in``;
- ``arrested``: the object stayed put through ``hold_s`` seconds of hold: the arrest event
  (arrival spread, contacts, the displacement seen); the robots keep holding;
- ``done`` after ``settle_s`` more seconds of hold (when the mission is the capture alone).

The arrest is declared from estimates (contact, the object staying put); the dry run scores it
against ground truth, and the world never stops the object on the controller's word.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.events import ArrestEvent
from controller.mission.brace import Braces, brace_speed
from controller.mission.capture_phase import (
    CLOSED,
    CaptureSettings,
    CaptureState,
    Measures,
    advance,
    entered,
)
from controller.mission.detours import Detours
from controller.mission.guard import SafetyStage
from controller.mission.planners import InlinePlanners, Planners
from controller.mission.sequence import Cue, Sequencer
from controller.mission.summary import CaptureSummary
from controller.mission.types import Event, FleetView, Intent, MissionOutput, Phase
from controller.planning.approach import (
    STATION_GAP,
    PlannerParams,
    envelope,
    interception_times,
    plan_velocities,
    ray_first_hit,
    ray_to_convex,
    separate_stations,
    static_free_distance,
)

STATION_SLACK = 0.02  # m beyond the safety filter's margin a station keeps from walls, obstacles


@dataclass(frozen=True)
class Goals:
    """World-frame goals of the capture points at one object pose, (M, 2) each."""

    points: np.ndarray
    normals: np.ndarray
    stations: np.ndarray  # on the convex envelope (approach)
    touch: np.ndarray  # disc centres touching the surface (closing in)
    preload: np.ndarray  # disc centres ``preload_depth`` inside it (hold)
    shortfall: np.ndarray  # (M,) m a station lies beyond where a wall lets a robot stand


@dataclass
class CaptureMission:
    """Approach and arrest. ``points``/``normals`` (M, 2), object frame; ``assignment`` (M,)
    robot per point. Robots without a point stay still (the filter moves them out of harm)."""

    points: np.ndarray
    normals: np.ndarray
    assignment: np.ndarray
    cfg: FleetConfig
    rng: np.random.Generator
    settings: CaptureSettings | None = None
    guard: SafetyStage | None = None
    waypoints: dict[int, list[np.ndarray]] = field(default_factory=dict)
    planners: Planners | None = None  # the port the detours are asked of (None: at once)
    # the job's phase, read here and reported into (None: one of its own, a capture alone)
    sequencer: Sequencer | None = None
    bracing: np.ndarray | None = None  # (M,) the points whose robots brace (brace.py)

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
        self.params = PlannerParams.from_config(ap)
        self.assigned = np.zeros(self.n, bool)
        self.assigned[self.assignment] = True
        self.state = CaptureState(contact_t=np.full(len(self.points), np.nan))
        # alone (no job's sequencer): its own, at approach (its first tick announces it)
        self.seq = self.sequencer if self.sequencer is not None else Sequencer(Phase.APPROACH)
        self.heading: np.ndarray | None = None
        self.braces = Braces(len(self.points))  # robots bracing a fast object (brace.py)
        if self.bracing is not None:
            self.braces.on[:] = self.bracing
        planners = self.planners or InlinePlanners()
        self.detours = Detours(cfg, self.s, planners, self.obstacles, self.radii)  # stage 3
        self.last_distance: np.ndarray | None = None
        # stations keep the discs this far from walls and obstacles (what the safety filter
        # lets a robot reach, with a station gap to spare)
        self.static_clearance = self.radii[self.assignment] + ap.safety_margin + STATION_SLACK
        grow = float(self.static_clearance.max()) if len(self.assignment) else 0.0
        self.grown_obstacles = [envelope(p, grow, 8) for p in self.obstacles]
        self.bounds = cfg.bounds_array() if cfg.world.walls else None

    @property
    def phase(self) -> str:
        return self.seq.phase

    def keep_clock(self, t0: float | None) -> None:
        """A re-assignment: the approach begun at ``t0`` goes on (its timeout, no new start)."""
        self.state = replace(self.state, t0=t0)

    def wait(self, dt: float) -> None:
        """``dt`` s the job was held (an e-stop): not counted by the timeout, hold or settle."""
        st, keys = self.state, ("t0", "hold_t0", "arrest_t")
        later = {k: getattr(st, k) + dt for k in keys if getattr(st, k) is not None}
        self.state = replace(st, **later)

    # --- stage 1: the pose the goals ride on ------------------------------------------------
    def goal_pose(self, view: FleetView) -> np.ndarray:
        """The object's next pose (one tick ahead: a longer look-ahead puts trailing contacts
        inside it)."""
        if view.object_velocity is not None:
            return np.asarray(view.object_pose, float) + np.asarray(view.object_velocity) * self.dt
        if view.object_prediction is not None:
            return np.asarray(view.object_prediction, float)
        return np.asarray(view.object_pose, float)

    # --- stage 2: the goals -------------------------------------------------------------------
    def goals(self, pose: np.ndarray) -> Goals:
        """World capture points, normals, envelope stations and contact targets (M, 2 each)."""
        pts = geometry.transform(self.points, pose)
        nrm = self.normals @ geometry.rot(float(pose[2])).T
        world = geometry.transform(self.object_poly, pose)
        img = ray_to_convex(pts, nrm, envelope(world, self.cfg.approach.envelope_margin))
        r = self.radii[self.assignment]
        # a ray out of a deep notch crosses the object's own arm before it leaves the hull:
        # keep the station on the free part of the ray (the robot waits inside the notch)
        free = ray_first_hit(pts, nrm, world) - r - STATION_GAP
        # an object against a wall: the station stays where a robot can stand (off the wall)
        static = static_free_distance(
            pts, nrm, self.static_clearance, self.grown_obstacles, self.bounds
        )
        out = np.minimum(np.sum((img - pts) * nrm, axis=1), np.minimum(free, static))
        out = separate_stations(pts, nrm, out, r, self.s.station_gap)
        # a station the walls leave no room for (a point beside a wall the object touches) is
        # reached as near as the robot can get: the shortfall widens its arrival tolerance
        shortfall = np.maximum(out - static, 0.0)
        touch = pts + (r + self.s.station_gap)[:, None] * nrm
        preload = pts + (r - self.s.preload_depth)[:, None] * nrm
        return Goals(pts, nrm, pts + nrm * out[:, None], touch, preload, shortfall)

    # --- stage 4: targets and feed-forward of the phase --------------------------------------
    def point_velocity(self, view: FleetView, pose: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """World velocities (M, 2) of points riding on the object (its twist at them)."""
        ovel = np.zeros(3) if view.object_velocity is None else np.asarray(view.object_velocity)
        rel = xy - pose[:2]
        return ovel[:2] + ovel[2] * np.stack([-rel[:, 1], rel[:, 0]], 1)

    def targets(
        self, view: FleetView, pose: np.ndarray, goals: Goals
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Goal positions and velocities (N, 2) and the assigned robots' targets (M, 2):
        stations while approaching (aimed where the object will be when the robot gets there),
        contacts after, preload targets once in contact; detour waypoints first."""
        centers = view.poses[:, :2]
        a = self.assignment
        phase = self.phase
        tgt = goals.stations if phase == Phase.APPROACH else goals.touch
        vel = self.point_velocity(view, pose, tgt)
        if phase != Phase.APPROACH:  # creep the last centimetres, no feed-forward
            vel[self.gaps(view) < self.s.creep_gap] = 0.0
        cage = self.state.cage
        if phase != Phase.APPROACH and cage is not None:  # touching: still, no feed-forward
            caged = ~np.isnan(cage[:, 0])
            tgt, vel = np.where(caged[:, None], cage, tgt), np.where(caged[:, None], 0.0, vel)
        goal = centers.copy()
        gvel = np.zeros((self.n, 2))
        goal[a], gvel[a] = tgt, vel
        if phase == Phase.APPROACH:
            speed = self.s.speed_margin * self.max_speed[a]
            oncoming = self.cfg.approach.intercept == "oncoming"
            ovel = np.zeros(3) if view.object_velocity is None else view.object_velocity
            b = self.braces.on
            tgt = np.where(b[:, None], goals.touch, tgt)
            vel = np.where(b[:, None], self.point_velocity(view, pose, goals.touch), vel)
            h = self.s.intercept_horizon
            t = np.diag(interception_times(centers[a], tgt, vel, speed, h, oncoming))
            if b.any():  # a brace waits in the object's path, whatever the rule for the others
                t = np.where(b, np.diag(interception_times(centers[a], tgt, vel, speed, h)), t)
            loose = b & (self.gaps(view) > 2 * self.s.creep_gap)  # stopped: braces aim again
            loose &= 2 * float(np.hypot(*ovel[:2])) < brace_speed(self.cfg, self.assigned)
            goal[a] = self.braces.meet(tgt, vel, t, loose)
            gvel[a[b]] = 0.0
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
        avoid[self.assignment, -1] = self.phase == Phase.APPROACH and ~self.braces.on
        active = self.assigned & ~view.stale & view.present
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
        return vel

    # --- stage 6: what the phase logic reads ---------------------------------------------------
    def gaps(self, view: FleetView) -> np.ndarray:
        """Estimated gaps (M,) m between each assigned robot's disc and the object."""
        xy = view.poses[self.assignment, :2]
        world = geometry.transform(self.object_poly, np.asarray(view.object_pose, float))
        return geometry.polygon_signed_distance(xy, world) - self.radii[self.assignment]

    def measures(self, view: FleetView, tgt: np.ndarray, goals: Goals) -> Measures:
        xy = view.poses[self.assignment, :2]
        world = geometry.transform(self.object_poly, np.asarray(view.object_pose, float))
        gap = self.gaps(view)
        dist = np.linalg.norm(xy - tgt, axis=1)
        if self.phase == Phase.APPROACH:
            dist = np.maximum(dist - goals.shortfall, 0.0)
            touching = self.braces.on & (gap < 2 * self.s.creep_gap)
            dist[touching] = 0.0  # a brace touching: there
            if touching.any():  # the rest may stand off by the filter's margin to a brace
                dist = np.maximum(dist - 2 * self.cfg.approach.safety_margin, 0.0)
        self.last_distance = dist  # read by the capture job (a robot stuck on its way)
        return Measures(view.t, dist, goals.preload, gap, world, bool(self.waypoints))

    def _caged(self) -> np.ndarray | None:
        """Robots holding a frozen contact target (they keep their heading)."""
        cage = self.state.cage
        if cage is None or self.phase == Phase.APPROACH:
            return None
        out = np.zeros(self.n, bool)
        out[self.assignment] = ~np.isnan(cage[:, 0])
        return out

    # --- the two stages the node runs ---------------------------------------------------------
    def plan(self, view: FleetView) -> Intent:
        zero = np.zeros((self.n, 2))
        if view.object_pose is None or view.estop:
            return Intent.of(zero, self.phase, stop=True)
        events: list[Event] = []
        if self.state.t0 is None:  # this capture starts: the job (again) at approach
            self.state = replace(self.state, t0=view.t)
            cue = Cue.READY if self.phase == Phase.PLAN else Cue.REPLANNED
            events += self.seq.report(view.t, cue).events
        pose = self.goal_pose(view)
        goals = self.goals(pose)
        if not self.detours.planned:  # detours around static obstacles (planned once)
            self.detours.ask(view, self.assignment, view.poses[:, :2], goals.stations)
        if self.detours.job.pending:
            self.detours.take(view.t, self.waypoints)
        goal, gvel, tgt = self.targets(view, pose, goals)
        vel = self.projective(view, goal, gvel, pose)
        if self.detours.hold is not None:  # the blocked robots wait for their routes
            vel[self.detours.hold] = 0.0
        m = self.measures(view, tgt, goals)
        report = advance(self.state, m, self.s, self.phase)
        step = self.seq.report(m.t, report.cue, report.failure)
        self.state, moved = entered(report.state, step, m)
        contacts = [
            {"robot": view.ids[i], "point": [float(x) for x in p]}
            for i, p in zip(self.assignment, goals.points, strict=True)
        ]
        events += [
            replace(e, contacts=contacts) if isinstance(e, ArrestEvent) else e
            for e in report.events + moved
        ]
        failure, failed = self.seq.state.failure, self.phase == Phase.FAILED
        closed = self.phase in CLOSED
        touch, braced = self.braces.masks(self.n, self.assignment, m.gap, 2 * self.s.creep_gap)
        return Intent.of(
            vel,
            self.phase,
            events,
            object_pose=pose,
            touch=self.assigned if self.phase != Phase.APPROACH else touch,
            # a caging robot's barrier never pushes it off the object's estimate: the physics
            # keeps it out; it holds its ground
            overlap=float(self.radii.max()) if closed else 0.0,
            cage=closed or touch is not None,
            hold=self._caged() if self.phase != Phase.APPROACH else braced,
            done=self.phase == Phase.DONE,
            failed=failed,
            reason=failure.reason if failed and failure else "",
            arrest=step.fired and self.phase == Phase.ARRESTED,
            progress={
                "phase": str(self.phase),
                "max_distance_m": float(np.max(m.dist)),
                "max_gap_m": float(np.max(m.gap)),
            },
        )

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        assert self.guard is not None
        return self.guard.apply(view, intent)

    def summary(self) -> CaptureSummary:
        assert self.guard is not None
        st = self.state
        return CaptureSummary(
            phase=str(self.phase),
            arrival_spread_s=st.arrival_spread,
            arrest_time_s=st.arrest_t,
            hold_displacement_estimated_m=st.hold_displacement if st.hold_t0 else None,
            escapes=st.escapes,
            contacts_lost=st.releases,
            infeasible_filter_calls=self.guard.counters.infeasible,
        )
