"""The ideal world: no physics, simple kinematic contacts. Robots track their commands exactly
(a differential robot never moves sideways) and pass through each other (overlaps are measured by
``check`` and left for the verdict). The object is the only thing that collides:

- alive, it follows its script, but a step that would make it overlap a robot, an obstacle or a
  wall is not taken (it stops there, and a stopped object is thwarted: after
  ``object.motion.give_up_after`` seconds it goes limp, as in the physics world);
- limp, it moves only when pushed: robot discs that overlap it push it out (translation by the
  summed penetration, rotation by its moment over the mean radius), never into an obstacle.

Fast and exact, for logic tests of the controller (crazyswarm2's "ideal tracker" idea).
"""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from sim_backend.base import WorldCheck
from sim_backend.motion import GiveUp, ObjectScript, ScriptedObject

CONTACT_SLACK = 1e-3  # m: a resting contact is not an overlap


class IdealWorld(ScriptedObject):
    """Kinematic stand-in world with the ``sim_backend.base.World`` interface."""

    def __init__(self, cfg: FleetConfig):
        self.cfg = cfg
        self.dt = cfg.sim.timestep
        self._t = 0.0
        self._ids = cfg.robot_ids
        self._holonomic = np.array([r.kind == "omni" for r in cfg.robots], dtype=float)
        self._radius = np.array([r.radius for r in cfg.robots])
        self._pose = np.array([r.start for r in cfg.robots], dtype=float)
        self._vel = np.zeros((len(self._ids), 3))
        self._cmd = np.zeros((len(self._ids), 3))
        self._index = {rid: i for i, rid in enumerate(self._ids)}
        self._script = ObjectScript(cfg.object.motion, cfg.object.start)
        self._give_up = GiveUp.for_motion(cfg.object.motion)
        self._obj = np.array(cfg.object.start, dtype=float)
        self._obj_vel = np.zeros(3)
        self._poly = geometry.ensure_ccw(cfg.object_polygon())
        self._centroid = geometry.centroid(self._poly)
        self._rbar = float(np.mean(np.linalg.norm(self._poly - self._centroid, axis=1)))
        self._obstacles = cfg.obstacle_polygons()
        self._bounds = cfg.bounds_array() if cfg.world.walls else None

    @property
    def t(self) -> float:
        return self._t

    @property
    def robot_ids(self) -> tuple[str, ...]:
        return self._ids

    def set_command(self, robot_id: str, vx: float, vy: float, wz: float) -> None:
        self._cmd[self._index[robot_id]] = (vx, vy, wz)

    def step(self, duration: float) -> None:
        n = max(1, int(round(duration / self.dt)))
        for _ in range(n):
            th = self._pose[:, 2]
            c, s = np.cos(th), np.sin(th)
            lateral = self._cmd[:, 1] * self._holonomic  # a diff robot has no sideways motion
            vx = c * self._cmd[:, 0] - s * lateral
            vy = s * self._cmd[:, 0] + c * lateral
            self._vel = np.stack([vx, vy, self._cmd[:, 2]], axis=1)
            self._pose += self._vel * self.dt
            self._pose[:, 2] = geometry.wrap_angle(self._pose[:, 2])
            before = self._obj.copy()
            if self._give_up.alive:
                self._drive_object()
            else:
                self._push_object()
            self._clip_robots()
            self._obj_vel = (self._obj - before) / self.dt
            self._obj_vel[2] = geometry.wrap_angle(self._obj[2] - before[2]) / self.dt
            self._t += self.dt

    def _blocked(self, pose: np.ndarray, robots: bool) -> bool:
        """Whether the object at ``pose`` would overlap an obstacle or a wall (or a robot)."""
        world = geometry.transform(self._poly, pose)
        if geometry.polygon_clearance(world, self._obstacles, self._bounds) < -CONTACT_SLACK:
            return True
        if not robots:
            return False
        sd = geometry.polygon_signed_distance(self._pose[:, :2], world)
        return bool(np.any(sd < self._radius - CONTACT_SLACK))

    def _drive_object(self) -> None:
        """The live object follows its script unless the step would run it into something."""
        target = self._script.target_velocity(self._t, self._obj, self._pose[:, :2])
        nxt = self._obj + target * self.dt
        nxt[2] = geometry.wrap_angle(nxt[2])
        moved = not self._blocked(nxt, robots=True)
        if moved:
            self._obj = nxt
        actual = target if moved else np.zeros(3)
        pressed = not moved and self._blocked(self._obj, robots=True)
        self._give_up.update(self._t + self.dt, self.dt, target, actual, pushed=pressed)

    def _push_object(self) -> None:
        """The limp object is pushed out of the robot discs that overlap it."""
        world = geometry.transform(self._poly, self._obj)
        xy = self._pose[:, :2]
        sd = geometry.polygon_signed_distance(xy, world)
        depth = self._radius - sd
        touching = depth > CONTACT_SLACK
        if not np.any(touching):
            return
        a = world
        b = np.roll(world, -1, axis=0)
        d, closest = geometry.point_segment_distance(xy[touching], a, b)
        near = closest[np.arange(len(d)), np.argmin(d, axis=1)]
        out = xy[touching] - near  # from the boundary toward the robot centre (outside)
        inside = sd[touching] < 0
        out[inside] *= -1.0
        nrm = out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
        push = -nrm * (depth[touching] - CONTACT_SLACK)[:, None]  # moves the object away
        c = geometry.transform(self._centroid[None], self._obj)[0]
        lever = near - c
        # the mean of the pushes (a squeeze from both sides moves nothing)
        move = push.mean(axis=0)
        turn = np.mean(lever[:, 0] * push[:, 1] - lever[:, 1] * push[:, 0]) / self._rbar**2
        # rotate about the centroid, not the frame origin
        rel = self._obj[:2] - c
        cs, sn = np.cos(turn), np.sin(turn)
        nxt = np.array(
            [*(c + move + [cs * rel[0] - sn * rel[1], sn * rel[0] + cs * rel[1]]), self._obj[2]]
        )
        nxt[2] = geometry.wrap_angle(nxt[2] + turn)
        if not self._blocked(nxt, robots=False):
            self._obj = nxt

    def _clip_robots(self) -> None:
        """The object is solid: a robot disc still in it is put back on its surface."""
        world = geometry.transform(self._poly, self._obj)
        xy = self._pose[:, :2]
        sd = geometry.polygon_signed_distance(xy, world)
        inside = self._radius - sd > CONTACT_SLACK
        if not np.any(inside):
            return
        d, closest = geometry.point_segment_distance(xy[inside], world, np.roll(world, -1, 0))
        near = closest[np.arange(len(d)), np.argmin(d, axis=1)]
        out = xy[inside] - near
        out[sd[inside] < 0] *= -1.0
        nrm = out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
        self._pose[inside, :2] = near + nrm * (self._radius[inside] - CONTACT_SLACK)[:, None]

    def robot_pose(self, robot_id: str) -> np.ndarray:
        return self._pose[self._index[robot_id]].copy()

    def robot_velocity(self, robot_id: str) -> np.ndarray:
        return self._vel[self._index[robot_id]].copy()

    def object_pose(self) -> np.ndarray:
        return self._obj.copy()

    def object_velocity(self) -> np.ndarray:
        return self._obj_vel.copy()

    def contact_forces(self) -> dict[str, float]:
        """No forces in a kinematic world."""
        return {}

    def check(self) -> WorldCheck:
        return check_discs(
            self._ids,
            self._pose[:, :2],
            self._radius,
            self._poly,
            self._obj,
            self._obstacles,
            self.cfg.bounds_array(),
        )

    def close(self) -> None:
        pass


def check_discs(
    ids: tuple[str, ...],
    xy: np.ndarray,
    radius: np.ndarray,
    object_polygon: np.ndarray,
    object_pose: np.ndarray,
    obstacles: list[np.ndarray],
    bounds: np.ndarray,
    contact_slack: float = 1e-3,
) -> WorldCheck:
    """Safety figures for disc robots from their true positions (shared by every backend)."""
    min_clear = geometry.min_disc_gap(xy, radius)
    world_poly = geometry.transform(object_polygon, object_pose)
    sd = geometry.polygon_signed_distance(xy, world_poly)
    penetration = float(max(0.0, np.max(radius - sd)))
    hit = geometry.discs_touch_static(xy, radius, obstacles, bounds, contact_slack)
    clearance = geometry.polygon_clearance(world_poly, obstacles, bounds)
    touching = tuple(rid for rid, h in zip(ids, hit, strict=True) if h)
    return WorldCheck(min_clear, penetration, touching, clearance)
