"""The robots' hold on the object while it is carried (pure bookkeeping of the transport).

Who holds which contact (object frame), who is on its way to a new one along the lane around
the object (``moves``, ``targets``), what the last local plan told each robot (``actions``),
and who is gone. The stages of the transport read and change it through these methods; none
of them reads another stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView
from controller.planning.transport_model import ObjectModel, relocation_path
from controller.planning.transport_types import RobotState


@dataclass
class Contact:
    """A robot's contact on the object (object frame): a point and the inward push direction."""

    point: np.ndarray
    inward: np.ndarray


@dataclass(frozen=True)
class RobotOrder:
    """What a local plan tells one robot: its action and, when it keeps or takes a contact,
    that contact (``hold``: the contact it pushes at; ``relocate``: the one it goes to)."""

    robot: int
    action: str
    contact: Contact | None = None
    how: str = ""  # "hold", "relocate" or "" (the action alone)


@dataclass(frozen=True)
class GripSettings:
    """``contact_tolerance`` (m: a robot this close to its contact point is in contact),
    ``arrival_tolerance`` (m: a relocating robot this close to its contact arrived),
    ``waypoint_reached`` (m), ``park_margin`` (m beyond the lane's band where idle robots
    wait); a relocating or parking robot's speed is ``move_gain`` (1/s) times its distance to
    go plus ``move_floor`` (m/s), capped at its ``max_speed``."""

    contact_tolerance: float = 0.15
    arrival_tolerance: float = 0.03
    waypoint_reached: float = 0.08
    park_margin: float = 0.05
    move_gain: float = 1.5
    move_floor: float = 0.05


CONTACT_REACH = 0.03  # m: at the carry, a robot's disc this near the object's surface holds it
# a relocating robot within this many of its radii of its station, the straight line to it
# clear of the object (checked at this many points), goes straight in instead of by the lane
STRAIGHT_IN = 6.0
STRAIGHT_SAMPLES = 16


def touching(
    cfg: FleetConfig, object_pose, poses: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The robots whose discs are within ``reach`` m of the object's surface: their indices,
    their nearest boundary points and the outward normals there (object frame)."""
    pose = np.asarray(object_pose, float)
    poly = geometry.ensure_ccw(cfg.object_polygon())
    local = geometry.inverse_transform(np.asarray(poses)[:, :2], pose)
    d, closest = geometry.point_segment_distance(local, poly, np.roll(poly, -1, axis=0))
    j = np.argmin(d, axis=1)
    rows = np.arange(len(local))
    radii = np.array([r.radius for r in cfg.robots])
    held = np.flatnonzero(d[rows, j] - radii < reach)
    return held, closest[rows, j][held], geometry.outward_normals(poly)[j][held]


class Grip:
    """Every robot's part in the hold (the fleet in config order, indices 0..N-1)."""

    def __init__(
        self,
        cfg: FleetConfig,
        model: ObjectModel,
        s: GripSettings,
        held: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
    ) -> None:
        """``held`` (K,) the robots holding the object at ``points`` with outward ``normals``
        (K, 2, object frame); the others start free."""
        self.cfg, self.model, self.s = cfg, model, s
        self.n = len(cfg.robots)
        self.robots = np.arange(self.n)
        self.contacts: dict[int, Contact | None] = {i: None for i in range(self.n)}
        for i, p, nv in zip(np.asarray(held, int), points, normals, strict=True):
            self.contacts[int(i)] = Contact(np.asarray(p, float), -np.asarray(nv, float))
        self.actions: dict[int, str | None] = {i: None for i in range(self.n)}
        self.moves: dict[int, list[np.ndarray]] = {}  # robot -> object-frame path (relocating)
        self.targets: dict[int, Contact] = {}
        self.lost: set[int] = set()  # robots gone during the job
        # the room as a relocation's lane is checked against (built once, read every tick)
        self.obstacles = cfg.obstacle_polygons()
        self.bounds = cfg.bounds_array()
        self.relocations = 0

    def active(self) -> list[int]:
        return [i for i in range(self.n) if i not in self.lost]

    def drop(self, i: int) -> None:
        """A robot gone: no contact, no path, no part in the next arrangement."""
        self.lost.add(i)
        self.contacts[i] = None
        self.moves.pop(i, None)
        self.targets.pop(i, None)
        self.actions[i] = None

    def touching(self) -> np.ndarray:
        """(N,) robots holding a contact."""
        return np.array([self.contacts[i] is not None for i in range(self.n)])

    def pushing(self) -> list[int]:
        """The robots holding a contact with the plan's action ``push`` (indices)."""
        return [i for i in range(self.n) if self.contacts[i] and self.actions[i] == "push"]

    def contact_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The contacts held: points, inward normals (object frame) and the robots' forces."""
        pts, nrm, fmax = [], [], []
        for i, c in self.contacts.items():
            if c is not None:
                pts.append(c.point)
                nrm.append(c.inward)
                fmax.append(self.cfg.robots[i].max_force)
        return np.reshape(pts, (-1, 2)), np.reshape(nrm, (-1, 2)), np.asarray(fmax, float)

    def unplan(self) -> None:
        """New contacts asked for: every path and target given up (the robots hold)."""
        self.targets.clear()
        self.moves.clear()

    def regrip(self, view: FleetView, pose: np.ndarray, pts: np.ndarray, nrm: np.ndarray):
        """New contacts (``pts``, outward ``nrm``, object frame): the robots nearest to them
        move there, the others keep their contacts (one too close to a new contact lets go)."""
        cfg = self.cfg
        r = cfg.max_robot_radius
        ids = self.active()
        here = geometry.inverse_transform(view.poses[ids, :2], pose)
        cost = np.linalg.norm(here[:, None] - (pts + r * nrm)[None], axis=-1)
        rows, cols = linear_sum_assignment(cost)
        chosen = set()
        for row, col in zip(rows, cols, strict=True):
            i = ids[row]
            chosen.add(i)
            self.targets[i] = Contact(pts[col], -nrm[col])
            if cost[row, col] > self.s.arrival_tolerance:
                end = pts[col] + cfg.robots[i].radius * nrm[col]
                self.moves[i] = list(relocation_path(self.model, here[row], end))
                self.contacts[i] = None
                self.relocations += 1
        centres = pts + r * nrm
        for i in ids:
            c = self.contacts[i]
            if i in chosen or c is None:
                continue
            mine = c.point - r * c.inward
            if np.any(np.linalg.norm(centres - mine, axis=1) < 2 * r + cfg.capture.clearance):
                self.contacts[i] = None  # in the way of a new contact: it lets go

    def settle(self) -> None:
        """Every robot at its new contact: the targets become the contacts."""
        for i, c in self.targets.items():
            self.contacts[i] = c
        self.targets.clear()

    def follow_plan(self, orders: list[RobotOrder], view: FleetView, pose: np.ndarray) -> None:
        """A local plan's orders, robot by robot in order: each robot's action, then the
        contact it holds or the one it relocates to."""
        for o in orders:
            self.actions[o.robot] = o.action
            if o.how == "hold":
                self.contacts[o.robot] = o.contact
            elif o.how == "relocate":
                self.relocate(o.robot, o.contact, view, pose)

    def relocate(self, i: int, target: Contact, view: FleetView, pose: np.ndarray) -> None:
        """A robot the plan relocates goes to that contact along the lane around the object,
        and keeps to it until it arrives (a plan made every interval would otherwise move the
        target before it gets there)."""
        r = self.cfg.robots[i].radius
        start = geometry.inverse_transform(view.poses[i, None, :2], pose)[0]
        end = target.point - r * target.inward
        cur = self.contacts[i]
        if cur is not None and np.linalg.norm(cur.point - target.point) < 2 * r:
            self.contacts[i] = target  # a short move along the boundary: stay attached
            return
        self.moves[i] = list(relocation_path(self.model, start, end))
        self.targets[i] = target
        self.contacts[i] = None
        self.relocations += 1

    def follow_paths(
        self, view: FleetView, pose: np.ndarray, vel: np.ndarray, touch: np.ndarray
    ) -> None:
        """Robots on a committed path: pure pursuit of its next point; arrival attaches them;
        on the last leg a robot may touch the object (it is coming to its contact)."""
        for i, path in list(self.moves.items()):
            here = view.poses[i, :2]
            if len(path) > 2 and self._lane_blocked(i, pose, path):
                if self._straight_in(i, here, pose, path[-1]):
                    del path[1:-1]  # the lane runs into an obstacle: straight in instead
            world = geometry.transform(np.asarray(path), pose)
            while len(world) > 1 and np.linalg.norm(world[0] - here) < self.s.waypoint_reached:
                path.pop(0)
                world = world[1:]
            err = world[0] - here
            dist = float(np.linalg.norm(err))
            if len(world) == 1 and dist < self.s.arrival_tolerance:
                del self.moves[i]
                self.contacts[i] = self.targets.pop(i)
                continue
            speed = min(self.s.move_gain * dist + self.s.move_floor, self.cfg.robots[i].max_speed)
            vel[i] = err / max(dist, 1e-9) * speed
            touch[i] = len(world) <= 2

    def _lane_blocked(self, i: int, pose: np.ndarray, path: list[np.ndarray]) -> bool:
        """Whether a point of robot ``i``'s remaining lane path puts its disc within the safety
        margin of an obstacle or a wall (the lane is drawn round the object alone)."""
        pts = geometry.transform(np.asarray(path[1:-1]), pose)
        r = self.cfg.robots[i].radius + self.cfg.approach.safety_margin
        return bool(geometry.discs_touch_static(pts, r, self.obstacles, self.bounds).any())

    def _straight_in(self, i: int, here: np.ndarray, pose: np.ndarray, end: np.ndarray) -> bool:
        """Whether robot ``i`` at ``here`` (world) can go straight to its path's ``end`` (its
        station beside the contact, object frame) with its disc clear of the object all the
        way: a robot near its contact on the same side whose lane runs into an obstacle takes
        the straight line (a crate stopped beside a bench left a robot squeezed between them,
        its lane point inside the bench's margin, stalling the job until the re-arrangement
        timed out)."""
        a = geometry.inverse_transform(here[None], pose)[0]
        b = np.asarray(end, float)
        if np.linalg.norm(b - a) > STRAIGHT_IN * self.cfg.robots[i].radius:
            return False
        ts = np.linspace(0.0, 1.0, STRAIGHT_SAMPLES)[:, None]
        gap = geometry.polygon_signed_distance(a + ts * (b - a), self.model.polygon)
        return bool(gap.min() >= self.cfg.robots[i].radius - self.s.arrival_tolerance)

    def park(self, view: FleetView, pose: np.ndarray, vel: np.ndarray, hold: np.ndarray) -> None:
        """Robots without a contact or a path leave the relocation lane: each one whose disc
        reaches into the lane's band backs straight away from the object until it is clear
        (a robot left on the lane where its last path ended blocks every path that passes)."""
        if not self.moves:
            return
        m, r = self.model, self.cfg.max_robot_radius
        clear = 5.0 * r + self.s.park_margin  # the lane at 3r: its robots reach out to 4r
        hull = geometry.convex_hull(m.polygon)
        for i in range(self.n):
            if i in self.moves or self.contacts[i] is not None or i in self.lost:
                continue
            local = geometry.inverse_transform(view.poses[i, None, :2], pose)
            d, closest = geometry.point_segment_distance(local, hull, np.roll(hull, -1, axis=0))
            k = int(np.argmin(d[0]))
            if d[0, k] >= clear or geometry.points_in_polygon(local, hull)[0]:
                continue
            out = (local[0] - closest[0, k]) / max(float(d[0, k]), 1e-9)
            go = clear - float(d[0, k])
            speed = min(self.s.move_gain * go + self.s.move_floor, self.cfg.robots[i].max_speed)
            vel[i] = geometry.rot(float(pose[2])) @ out * speed
            hold[i] = False

    def robot_states(self, view: FleetView) -> tuple[RobotState, ...]:
        """Every robot as the local planner sees it (a robot off its contact point is free)."""
        out = []
        pose = np.asarray(view.object_pose, float)
        for i in range(self.n):
            r = self.cfg.robots[i]
            c = self.contacts[i]
            if c is not None:
                centre = geometry.transform((c.point - r.radius * c.inward)[None], pose)[0]
                if np.linalg.norm(centre - view.poses[i, :2]) > self.s.contact_tolerance:
                    c = None  # it lost its contact: the planner knows it as free
            target = self.targets.get(i) if i in self.moves else None
            out.append(
                RobotState(
                    position=view.poses[i, :2].copy(),
                    radius=r.radius,
                    max_force=r.max_force,
                    max_speed=r.max_speed,
                    contact=None if c is None else (c.point, c.inward),
                    action="relocate"
                    if i in self.moves
                    else ("idle" if i in self.lost else self.actions[i]),
                    id=r.id,
                    target=None if target is None else (target.point, target.inward),
                )
            )
        return tuple(out)
