"""CaptureMission: approach a moving object, close in on the capture points, arrest it (§3).

Pure per-tick mission: ``step(view) -> MissionOutput``. Phases: ``approach`` (chase each
point's image on the convex envelope, then keep station there) -> ``close_in`` (all robots on
the envelope: every one moves to its contact point, point + (r + gap)·n) -> ``arrested`` (every
robot within ``contact_tolerance`` of its contact point; the arrest event carries the arrival
spread) -> ``done`` after a short settle. Every command goes through the CBF safety filter.

Timing statistics need a clock; the mission never reads one itself: pass ``clock`` (e.g.
``time.perf_counter`` from the composition root or a benchmark) to get them in ``summary()``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller import geometry
from controller.mission.tracking import RobotLimits, track_reversible
from controller.mission.types import FleetView, MissionOutput
from controller.planning.approach import (
    STATION_GAP,
    PlannerParams,
    envelope,
    limit_accel,
    plan_velocities,
    ray_first_hit,
    ray_to_convex,
    separate_stations,
)
from controller.planning.safety import SafetyFilter


@dataclass
class CaptureMission:
    """Approach and arrest. ``points``/``normals`` (M, 2) in the object frame; ``assignment``
    (M,) robot index per point. Robots without a point stay still (the filter still moves them
    out of harm's way)."""

    points: np.ndarray
    normals: np.ndarray
    assignment: np.ndarray
    cfg: Any
    rng: np.random.Generator
    clock: Callable[[], float] | None = None
    contact_gap: float = 0.015
    settle_s: float = 0.5
    phase: str = "approach"
    _times: dict[str, list[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cfg = self.cfg
        ap = cfg.approach
        self.points = np.asarray(self.points, float)
        nrm = np.asarray(self.normals, float)
        self.normals = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        self.assignment = np.asarray(self.assignment, int)
        self.limits = RobotLimits.from_config(cfg.robots)
        self.n = len(cfg.robots)
        self.radii = np.array([r.radius for r in cfg.robots], float)
        self.max_accel = np.minimum(self.limits.max_accel, ap.max_accel)
        self.dt = 1.0 / cfg.fleet.rate_hz
        self.obstacles = [geometry.ensure_ccw(p) for p in cfg.obstacle_polygons()]
        self.object_poly = geometry.ensure_ccw(cfg.object_polygon())
        self.params = PlannerParams(
            max_turn=np.deg2rad(ap.max_turn_deg),
            projection=ap.projection,
            alpha=np.deg2rad(ap.alpha_deg),
            alpha_growth=ap.alpha_growth,
            alpha_max=np.deg2rad(ap.alpha_max_deg),
        )
        self.filter = SafetyFilter(
            self.radii,
            self.limits.max_speed,
            cfg.bounds_array(),
            len(self.obstacles) + 1,
            margin=ap.safety_margin,
        )
        self.assigned = np.zeros(self.n, bool)
        self.assigned[self.assignment] = True
        self.t0: float | None = None
        self.heading: np.ndarray | None = None
        self.v_prev = np.zeros((self.n, 2))
        self.contact_t = np.full(len(self.points), np.nan)
        self.arrest_t: float | None = None
        self.arrival_spread: float | None = None
        self.waypoints: dict[int, list[np.ndarray]] = {}
        self._routes_planned = False
        self.events_count: dict[str, int] = {}
        self.infeasible = 0
        self.min_filter_status = "solved"

    # --- geometry of the goals -------------------------------------------------------------
    def goals(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World capture points, normals, envelope images and contact targets (M, 2 each)."""
        pts = geometry.transform(self.points, pose)
        nrm = self.normals @ geometry.rot(float(pose[2])).T
        env = envelope(
            geometry.transform(self.object_poly, pose), self.cfg.approach.envelope_margin
        )
        img = ray_to_convex(pts, nrm, env)
        r = self.radii[self.assignment]
        contact = pts + (r + self.contact_gap)[:, None] * nrm
        # a ray out of a deep notch crosses the object's own arm before it leaves the hull:
        # keep the image on the free part of the ray (the robot waits inside the notch)
        world = geometry.transform(self.object_poly, pose)
        free = ray_first_hit(pts, nrm, world) - r - STATION_GAP
        out = np.minimum(np.sum((img - pts) * nrm, axis=1), free)
        out = separate_stations(pts, nrm, out, r, self.contact_gap)
        img = pts + nrm * out[:, None]
        return pts, nrm, img, contact

    def _plan_routes(self, centers: np.ndarray, img: np.ndarray) -> None:
        """RobotRoadmap routes for robots whose straight line to their image is blocked."""
        from controller.planning.roadmap import RobotRoadmap

        self._routes_planned = True
        blocked = []
        for m, i in enumerate(self.assignment):
            for poly in self.obstacles:
                grown = envelope(poly, self.radii[i] + 0.05, samples=8)
                seg = np.linspace(centers[i], img[m], 50)
                if geometry.points_in_polygon(seg, grown).any():
                    blocked.append((m, i))
                    break
        if not blocked:
            return
        rr = float(self.radii.max()) + self.cfg.approach.safety_margin + 0.05
        rm = RobotRoadmap.build(
            self.cfg.bounds_array(), self.obstacles, rr, self.cfg.route.robot_resolution
        )
        for m, i in blocked:
            res = rm.plan(centers[i], img[m], subgoal_spacing=0.6)
            if res.status == "ok":
                self.waypoints[i] = [w[:2] for w in res.subgoals[:-1]]

    # --- the step ----------------------------------------------------------------------------
    def step(self, view: FleetView) -> MissionOutput:
        tic = self.clock() if self.clock else 0.0
        n = self.n
        events: list[tuple[str, dict[str, Any]]] = []
        if view.object_pose is None or view.estop:
            self.v_prev[:] = 0.0
            return MissionOutput(np.zeros((n, 3)), self.phase)
        if self.t0 is None:
            self.t0 = view.t
            events.append(("phase", {"phase": self.phase, "t": view.t}))
        ovel = np.zeros(3) if view.object_velocity is None else np.asarray(view.object_velocity)
        # goals ride on the object's next pose (one tick ahead): a longer look-ahead would put
        # the trailing robots' contact points inside the object as it is now
        if view.object_velocity is not None:
            pose = np.asarray(view.object_pose, float) + ovel * self.dt
        elif view.object_prediction is not None:
            pose = np.asarray(view.object_prediction, float)
        else:
            pose = np.asarray(view.object_pose, float)
        centers = view.poses[:, :2]
        if self.heading is None:
            th = view.poses[:, 2]
            self.heading = np.stack([np.cos(th), np.sin(th)], 1)
        pts, nrm, img, contact = self.goals(pose)
        if not self._routes_planned:
            self._plan_routes(centers, img)
        a = self.assignment
        goal = centers.copy()
        gvel = np.zeros((n, 2))
        c = pose[:2]
        tgt = img if self.phase == "approach" else contact
        goal[a] = tgt
        rel = tgt - c
        gvel[a] = ovel[:2] + ovel[2] * np.stack([-rel[:, 1], rel[:, 0]], 1)
        # waypoints around static obstacles
        for i, wps in list(self.waypoints.items()):
            while wps and np.linalg.norm(centers[i] - wps[0]) < 0.15:
                wps.pop(0)
            if wps:
                goal[i] = wps[0]
                gvel[i] = 0.0
            else:
                del self.waypoints[i]
        dist = np.linalg.norm(centers[a] - tgt, axis=1)
        ap = self.cfg.approach
        obj_world = geometry.transform(self.object_poly, pose)
        polys = self.obstacles + [obj_world]
        avoid = np.ones((n, len(polys)), bool)
        exempt = np.zeros((n, len(polys)), bool)
        if self.phase != "approach":
            avoid[a, -1] = False
            exempt[a, -1] = True
        active = self.assigned & ~view.stale & view.present
        if self.phase == "arrested":
            active[:] = False
        t_plan = self.clock() if self.clock else 0.0
        vel, head, _ = plan_velocities(
            centers,
            self.heading,
            self.radii,
            self.limits.max_speed,
            goal,
            gvel,
            polys,
            avoid,
            active,
            self.params,
            self.rng,
        )
        if self.phase == "arrested":
            vel[a] = 0.0
        self.heading = head
        vel = limit_accel(vel, self.v_prev, self.max_accel, self.dt)
        t_filter = self.clock() if self.clock else 0.0
        stale = view.stale | ~view.present
        motion = [None] * len(self.obstacles) + [view.object_velocity]
        res = self.filter.filter(centers, vel, polys, exempt=exempt, stale=stale, motion=motion)
        t_end = self.clock() if self.clock else 0.0
        if res.stopped.any():
            self.infeasible += 1
            events.append(
                ("safety_stop", {"robots": [view.ids[i] for i in np.flatnonzero(res.stopped)]})
            )
        vel = res.velocities
        self.v_prev = vel
        cmds = track_reversible(view.poses, vel, self.limits)
        # phase logic
        arrest = False
        done = failed = False
        if self.phase == "approach":
            if np.all(dist < ap.envelope_tolerance) and not self.waypoints:
                self._set_phase("close_in", view.t, events)
        elif self.phase == "close_in":
            arrived = dist < ap.contact_tolerance
            first = arrived & np.isnan(self.contact_t)
            self.contact_t[first] = view.t
            if np.all(arrived):
                self.arrest_t = view.t
                self.arrival_spread = float(np.nanmax(self.contact_t) - np.nanmin(self.contact_t))
                self._set_phase("arrested", view.t, events)
                arrest = True
                events.append(
                    (
                        "arrest",
                        {
                            "t": view.t,
                            "arrival_spread_s": self.arrival_spread,
                            "contacts": [
                                {"robot": view.ids[i], "point": [float(x) for x in p]}
                                for i, p in zip(a, pts, strict=True)
                            ],
                        },
                    )
                )
        elif self.phase == "arrested":
            cmds[:] = 0.0
            if self.arrest_t is not None and view.t - self.arrest_t >= self.settle_s:
                done = True
                self._set_phase("done", view.t, events)
        done = done or self.phase == "done"  # stays done (a reader may miss one tick)
        if self.phase in ("approach", "close_in") and view.t - self.t0 > ap.timeout:
            failed = True
            self._set_phase("failed", view.t, events)
        cmds[stale] = 0.0
        if self.clock:
            self._times.setdefault("plan_s", []).append(t_filter - t_plan)
            self._times.setdefault("filter_s", []).append(t_end - t_filter)
            self._times.setdefault("step_s", []).append(self.clock() - tic)
        return MissionOutput(
            cmds, self.phase, events=events, done=done, failed=failed, arrest=arrest
        )

    def _set_phase(self, phase: str, t: float, events: list) -> None:
        self.phase = phase
        events.append(("phase", {"phase": phase, "t": t}))

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "phase": self.phase,
            "arrival_spread_s": self.arrival_spread,
            "arrest_time_s": self.arrest_t,
            "infeasible_filter_calls": self.infeasible,
        }
        for k, v in self._times.items():
            arr = np.asarray(v) * 1e3
            out[k.replace("_s", "_ms")] = {
                "median": float(np.median(arr)),
                "p90": float(np.percentile(arr, 90)),
                "max": float(arr.max()),
                "calls": len(arr),
            }
        return out
