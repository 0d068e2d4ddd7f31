"""The ideal world: no physics. Robots track their commands exactly (a differential robot never
moves sideways), the live object follows its script kinematically, the arrested object stays
where it is. Nothing collides: overlaps are measured by ``check`` and left for the verdict.

Fast and exact, for logic tests of the controller (crazyswarm2's "ideal tracker" idea).
"""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from sim_backend.base import WorldCheck
from sim_backend.motion import ObjectScript


class IdealWorld:
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
        self._obj = np.array(cfg.object.start, dtype=float)
        self._obj_vel = np.zeros(3)
        self._arrested = False
        self._poly = cfg.object_polygon()
        self._obstacles = cfg.obstacle_polygons()

    @property
    def t(self) -> float:
        return self._t

    @property
    def robot_ids(self) -> tuple[str, ...]:
        return self._ids

    @property
    def arrested(self) -> bool:
        return self._arrested

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
            if not self._arrested:
                v = self._script.target_velocity(self._t, self._obj, self._pose[:, :2])
                self._obj_vel = v
                self._obj = self._obj + v * self.dt
                self._obj[2] = geometry.wrap_angle(self._obj[2])
            else:
                self._obj_vel = np.zeros(3)
            self._t += self.dt

    def robot_pose(self, robot_id: str) -> np.ndarray:
        return self._pose[self._index[robot_id]].copy()

    def robot_velocity(self, robot_id: str) -> np.ndarray:
        return self._vel[self._index[robot_id]].copy()

    def object_pose(self) -> np.ndarray:
        return self._obj.copy()

    def object_velocity(self) -> np.ndarray:
        return self._obj_vel.copy()

    def arrest(self) -> None:
        self._arrested = True

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
    return WorldCheck(
        min_clear, penetration, tuple(rid for rid, h in zip(ids, hit, strict=True) if h)
    )
