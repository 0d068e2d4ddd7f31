"""The capture mission: approach the moving object, close in together, arrest it (pure).

Phases (Sharma et al. §3 with the issue's corrections):

- ``approach``: every assigned robot chases its capture point's image on the convex envelope
  (the object's predicted pose), by projective path planning; on reaching it, it matches the
  object's velocity and keeps station.
- ``close_in``: once every assigned robot is on station at the same time, all move in together
  to their contact points (current pose, velocity fed forward).
- ``arrested``: every assigned robot is within ``contact_tolerance`` of its contact point at
  once: the ``arrest`` event (arrival spread = time between the first and the last robot's
  first contact) and ``arrest=True``; the robots hold and the mission is done after
  ``settle_time``.

Every command passes the safety filter (``controller.safety``); unassigned robots stay put and
are obstacles like any other robot. ``failed`` after ``approach.timeout`` seconds without an
arrest. Time comes from the view; randomness from the generator passed in.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller import geometry
from controller.approach import ApproachParams, capture_goals, plan_step
from controller.config import FleetConfig
from controller.mission import RobotLimits, world_to_body
from controller.node import FleetView, MissionOutput
from controller.safety import SafetyFilter, SafetyParams


class CaptureMission:
    def __init__(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        assignment: np.ndarray,
        cfg: FleetConfig,
        rng: np.random.Generator,
    ) -> None:
        self.cfg = cfg
        self.points = np.asarray(points, dtype=float)
        self.normals = np.asarray(normals, dtype=float)
        self.assignment = np.asarray(assignment, dtype=int)
        if len(set(self.assignment.tolist())) != len(self.assignment):
            raise ValueError("assignment: a robot is assigned twice")
        self.rng = rng
        self.n = len(cfg.robots)
        self.params = ApproachParams.from_config(cfg.approach)
        self.limits = RobotLimits.from_config(cfg.robots)
        self.radii = np.array([r.radius for r in cfg.robots])
        self.polygon = cfg.object_polygon()
        self.obstacles = cfg.obstacle_polygons()
        self.filter = SafetyFilter(
            self.radii,
            self.limits.holonomic,
            self.limits.max_speed,
            cfg.bounds_array(),
            self.obstacles,
            SafetyParams.from_config(cfg),
        )
        self.assigned = np.zeros(self.n, bool)
        self.assigned[self.assignment] = True
        a = cfg.approach
        self.contact_tol = a.contact_tolerance
        self.envelope_tol = a.envelope_tolerance
        self.timeout = a.timeout
        self.settle = a.settle_time
        self.close_speed = a.close_in_speed
        self.lookahead = a.lookahead
        self.phase = "approach"
        self.t0: float | None = None
        self.first_contact = np.full(self.n, np.nan)
        self.arrest_t: float | None = None
        self.spread: float | None = None
        self.heading: np.ndarray | None = None
        self.last_v = np.zeros((self.n, 2))
        self.infeasible_events = 0
        self.rules: dict[str, int] = {}

    # -- helpers
    def _filtered_points(self, poses: np.ndarray) -> np.ndarray:
        la = np.where(self.limits.holonomic, 0.0, self.lookahead)
        return poses[:, :2] + la[:, None] * np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], 1)

    def _commands(self, poses: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """World velocities of the filtered points → body commands under the robots' limits."""
        lim = self.limits
        # acceleration limit on the world velocity
        dv = v - self.last_v
        step = lim.max_accel * dt
        mag = np.linalg.norm(dv, axis=1)
        k = np.where(mag > step, step / np.maximum(mag, 1e-12), 1.0)
        v = self.last_v + dv * k[:, None]
        self.last_v = v
        th = poses[:, 2]
        body = world_to_body(th, v)
        cmds = np.zeros((self.n, 3))
        omni = lim.holonomic
        cmds[omni, :2] = body[omni]
        # differential: the look-ahead point is holonomic: v = ṗ·h, ω = ṗ·h⊥ / ℓ
        diff = ~omni
        cmds[diff, 0] = body[diff, 0]
        cmds[diff, 2] = body[diff, 1] / self.lookahead
        # scale (v, ω) together, never clip one alone: the look-ahead point then still moves
        # along the filtered direction, only slower, and every barrier condition with h ≥ 0
        # still holds (∇h·kv ≥ −kγh ≥ −γh for 0 < k ≤ 1)
        sp = np.linalg.norm(cmds[:, :2], axis=1)
        k = np.where(sp > lim.max_speed, lim.max_speed / np.maximum(sp, 1e-12), 1.0)
        wz = np.abs(cmds[:, 2])
        k = np.minimum(
            k, np.where(wz > lim.max_yaw_rate, lim.max_yaw_rate / np.maximum(wz, 1e-12), 1.0)
        )
        cmds *= k[:, None]
        return cmds

    # -- the tick
    def step(self, view: FleetView) -> MissionOutput:
        zero = np.zeros((self.n, 3))
        events: list[tuple[str, dict[str, Any]]] = []
        if self.t0 is None:
            self.t0 = view.t
            self.heading = view.poses[:, 2].copy()
        dt = 1.0 / self.cfg.fleet.rate_hz
        if self.phase == "arrested":
            done = view.t - (self.arrest_t or view.t) >= self.settle
            self.last_v[:] = 0.0
            return MissionOutput(zero, "arrested", done=done)
        if view.object_pose is None:
            return MissionOutput(zero, self.phase)
        if view.t - self.t0 > self.timeout:
            return MissionOutput(
                zero, self.phase, [("failed", {"reason": "timeout", "after_s": self.timeout})],
                failed=True,
            )  # fmt: skip
        poses = view.poses
        live = view.present & ~view.stale
        obj_now = view.object_pose
        obj_vel = view.object_velocity if view.object_velocity is not None else np.zeros(3)
        obj_pred = view.object_prediction if view.object_prediction is not None else obj_now
        r_as = self.radii[self.assignment]
        env_pred, _ = capture_goals(
            self.points, self.normals, r_as, obj_pred, self.polygon, self.params
        )
        env_now, contact_now = capture_goals(
            self.points, self.normals, r_as, obj_now, self.polygon, self.params
        )
        # velocity of each goal point (rigid motion of the object)
        c = geometry.transform(geometry.centroid(self.polygon)[None], obj_now)[0]
        goal_v_env = obj_vel[:2] + obj_vel[2] * np.stack(
            [-(env_now[:, 1] - c[1]), env_now[:, 0] - c[0]], 1
        )
        pos = poses[:, :2]
        idx = self.assignment
        on_station = np.linalg.norm(pos[idx] - env_now, axis=1) < self.envelope_tol
        in_contact = np.linalg.norm(pos[idx] - contact_now, axis=1) < self.contact_tol
        if self.phase == "approach" and np.all(on_station) and np.all(live[idx]):
            self.phase = "close_in"
            events.append(("phase", {"phase": "close_in", "t": view.t}))
        goals = pos.copy()
        goal_v = np.zeros((self.n, 2))
        speed = self.limits.max_speed.copy()
        active = np.zeros(self.n, bool)
        closing = np.zeros(self.n, bool)
        object_world = geometry.transform(self.polygon, obj_now)
        v_nom = np.zeros((self.n, 2))
        if self.phase == "approach":
            goals[idx] = env_pred
            goal_v[idx] = goal_v_env
            active[idx] = live[idx]
            # robots on station keep it: track the envelope point with feed-forward
            st = idx[on_station]
            res = plan_step(
                pos, self.radii, goals, goal_v, speed, self.heading, self.obstacles,
                active & ~np.isin(np.arange(self.n), st), self.params, self.rng,
                avoid_object=np.ones(self.n, bool),
                object_polygon=geometry.transform(self.polygon, obj_pred),
            )  # fmt: skip
            v_nom = res.velocity
            v_nom[st] = goal_v_env[on_station] + self.params.gain * (env_now[on_station] - pos[st])
            self.heading = res.heading
            for r in res.rules:
                self.rules[r] = self.rules.get(r, 0) + 1
        else:  # close_in: straight in along the normals, velocity fed forward
            closing[idx] = True
            goal_v_c = obj_vel[:2] + obj_vel[2] * np.stack(
                [-(contact_now[:, 1] - c[1]), contact_now[:, 0] - c[0]], 1
            )
            # the closing speed (relative to the object) is capped, not the feed-forward: a
            # robot behind a fast object must still gain on it
            err = contact_now - pos[idx]
            v_rel = self.params.gain * err
            cap = self.close_speed * self.limits.max_speed[idx]
            sp = np.linalg.norm(v_rel, axis=1)
            v_rel *= np.where(sp > cap, cap / np.maximum(sp, 1e-12), 1.0)[:, None]
            v_nom[idx] = goal_v_c + v_rel
            newly = in_contact & np.isnan(self.first_contact[idx])
            self.first_contact[idx[newly]] = view.t
        # diff robots: the filter works on the look-ahead point
        fr = self.filter.filter(
            self._filtered_points(poses),
            v_nom,
            stale=~live,
            object_polygon=object_world,
            object_velocity=obj_vel,
            object_exempt=closing,
            closing=closing,
            centres=poses[:, :2],
            headings=poses[:, 2],
        )
        if fr.status != "solved":
            self.infeasible_events += 1
            events.append(("safety_stop", {"status": fr.status, "t": view.t}))
        cmds = self._commands(poses, fr.velocities, dt)
        cmds[~live] = 0.0
        arrest = False
        if self.phase == "close_in" and np.all(in_contact):
            self.phase = "arrested"
            self.arrest_t = view.t
            self.spread = float(
                np.nanmax(self.first_contact[idx]) - np.nanmin(self.first_contact[idx])
            )
            arrest = True
            cmds[:] = 0.0
            self.last_v[:] = 0.0
            events.append(
                ("arrest", {
                    "t": view.t,
                    "arrival_spread_s": self.spread,
                    "robots": [view.ids[i] for i in idx],
                    "contact_error_m": float(np.max(np.linalg.norm(pos[idx] - contact_now, 1))),
                })
            )  # fmt: skip
        return MissionOutput(cmds, self.phase, events, arrest=arrest)

    def summary(self) -> dict[str, Any]:
        return {
            "phase": self.phase,
            "arrest_time_s": self.arrest_t,
            "arrival_spread_s": self.spread,
            "safety_infeasible": self.infeasible_events,
            "rules": dict(self.rules),
            "safety_solves": self.filter.solves,
        }
