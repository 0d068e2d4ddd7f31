"""The pybullet stand-in world: disc robots with bounded push force, a polygonal object on a floor.

Modelling choices (each measured on this machine, see tests/test_sim_world.py):

- **Robots** are cylinders of their radius on a fixed-base chain of force-limited velocity
  motors (no floor contact; they float 15 mm up and touch only the object, each other, walls and
  obstacles). An omni robot: prismatic X, prismatic Y, revolute Z; its body-frame command is
  turned into world X/Y targets, re-aimed as its heading changes, each axis bounded by
  ``max_force``. A differential robot: X and Y held at zero velocity by tyre-like locks bounded
  by ``tyre_grip`` · m · g, revolute Z, then a prismatic F along its heading driven at v and
  bounded by ``max_force``: it never moves sideways unless pushed harder than its tyres hold.
  Its F offset is folded back into X/Y ("re-basing") whenever it exceeds ``rebase_distance``
  (1 mm, checked every ``control_every`` physics steps) so that it turns about its own centre.
  The heading motor's torque is bounded by ``max_force`` · radius. The chain links weigh a
  tenth of the robot each: much lighter links make the solver stall the motors well below their
  force bound.
- **The object** is one multibody: its polygon is split into convex pieces (constrained Delaunay
  triangles merged by Hertel–Mehlhorn) and each piece is a convex prism link, so an L or U keeps
  its notch. The whole mass and the planar inertia of the real shape sit on the base, with the
  centre of mass at the polygon's area centroid (the piece links carry a negligible mass, because
  pybullet's ``changeDynamics(localInertiaDiagonal=...)`` on a link writes the base's inertia).
- **Floor friction** goes through three small skid spheres under the object, centred on the
  centroid at the polygon's mean radius from it, while the prisms ride 12 mm above the floor. Three
  points make the normal load statically determinate (m·g/3 each), so the force to slide the
  object is μ_floor·m·g (measured within 1 %) and the torque to spin it μ_floor·m·g·r̄ (uniform
  pressure), instead of the 0.75–1.0 spread a prism resting on its own faces shows in pybullet.
  Contact friction is the product of the two coefficients: skids carry μ_floor, the floor 1; the
  object's prisms carry 1 and robots ``object.contact_friction``.
- **The live object** propels itself: its skids are frictionless and a force-limited tracker
  (``object.motion.max_force``; torque limited to that force times the radius of gyration) pushes
  its centre of mass along ``ObjectScript.target_velocity``. It keeps fighting a hold (or a wall)
  until it has been thwarted for ``object.motion.give_up_after`` seconds in a row
  (``sim_backend.motion.GiveUp``); then its drive switches off and the skid friction on: from then
  on it is "compromised" and moves only when pushed. Nothing the controller declares changes the
  object: the physics decides whether it is held.

Poses are those of the polygon's own frame (not the centre of mass), so ``object.start`` places
the polygon exactly as written.
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import shapely

from controller import geometry
from controller.config import FleetConfig
from controller.geometry import wrap_angle
from sim_backend.base import WorldCheck
from sim_backend.ideal import check_discs
from sim_backend.motion import GiveUp, ObjectScript, ScriptedObject

GRAVITY = 9.81  # m/s^2

# Heights (m). Robots and prisms float above the floor; only the object's skids touch it.
SKID_RADIUS = 0.005
OBJECT_LIFT = 2 * SKID_RADIUS + 0.002  # bottom face of the object's prisms
ROBOT_LIFT = OBJECT_LIFT + 0.003  # bottom face of the robot cylinders
ROBOT_HEIGHT = 0.1
WALL_THICKNESS = 0.1
WALL_HEIGHT = 0.3
STATIC_FRICTION = 0.3  # walls and obstacles

_LIGHT = 1e-3  # mass fraction of each of the object's piece and skid links
_CHAIN = 0.1  # mass fraction of each robot chain link (solver conditioning)


class ConvexDecompositionError(ValueError):
    """The polygon could not be split into convex pieces (degenerate input)."""


# --------------------------------------------------------------------------- pure geometry


def _is_convex(poly: np.ndarray, tol: float = 1e-12) -> bool:
    p = poly
    a = np.roll(p, 1, axis=0)
    b = np.roll(p, -1, axis=0)
    cross = (p[:, 0] - a[:, 0]) * (b[:, 1] - p[:, 1]) - (p[:, 1] - a[:, 1]) * (b[:, 0] - p[:, 0])
    return bool(np.all(cross >= -tol))


def convex_pieces(polygon: np.ndarray) -> list[np.ndarray]:
    """Split a simple polygon (n, 2) into convex counter-clockwise pieces that tile it exactly.

    Constrained Delaunay triangulation (shapely) followed by Hertel–Mehlhorn merging: two pieces
    sharing an edge are merged whenever the union stays convex (at most 4x the optimal count).
    """
    poly = geometry.ensure_ccw(np.asarray(polygon, dtype=float))
    if _is_convex(poly):
        return [poly]
    tris = shapely.constrained_delaunay_triangles(shapely.Polygon(poly))
    pieces: list[list[int]] = []
    for tri in shapely.get_parts(tris):
        xy = np.asarray(tri.exterior.coords)[:3]
        idx = [int(np.argmin(np.linalg.norm(poly - q, axis=1))) for q in xy]
        if len(set(idx)) != 3:
            raise ConvexDecompositionError(f"degenerate triangle {xy.tolist()} in polygon")
        if geometry.signed_area(poly[idx]) < 0:
            idx.reverse()
        pieces.append(idx)
    merged = True
    while merged:
        merged = False
        for i in range(len(pieces)):
            for j in range(i + 1, len(pieces)):
                union = _merge(pieces[i], pieces[j])
                if union is not None and _is_convex(poly[union]):
                    pieces[i] = union
                    del pieces[j]
                    merged = True
                    break
            if merged:
                break
    return [poly[idx] for idx in pieces]


def _merge(a: list[int], b: list[int]) -> list[int] | None:
    """Union of two CCW index cycles sharing an edge (u, v) in ``a`` and (v, u) in ``b``."""
    na, nb = len(a), len(b)
    for k in range(na):
        u, v = a[k], a[(k + 1) % na]
        for m in range(nb):
            if b[m] == v and b[(m + 1) % nb] == u:
                outer = [a[(k + 1 + s) % na] for s in range(na)]  # v, ..., u
                inner = [b[(m + 2 + s) % nb] for s in range(nb - 2)]  # after u, before v
                return outer + inner
    return None


def mean_radius(polygon: np.ndarray, n: int = 200) -> float:
    """Mean distance (m) from the area centroid over the polygon's area (grid quadrature)."""
    poly = np.asarray(polygon, dtype=float)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    u = (np.arange(n) + 0.5) / n
    gx, gy = np.meshgrid(lo[0] + u * (hi[0] - lo[0]), lo[1] + u * (hi[1] - lo[1]))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inside = geometry.points_in_polygon(pts, poly)
    c = geometry.centroid(poly)
    return float(np.mean(np.linalg.norm(pts[inside] - c, axis=1)))


def yaw_of(quat: tuple[float, float, float, float]) -> float:
    """Heading (rad) of a quaternion (x, y, z, w) of a body that stays level."""
    x, y, z, w = quat
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_of(theta: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a rotation by ``theta`` (rad) about the world z axis."""
    return (0.0, 0.0, math.sin(theta / 2.0), math.cos(theta / 2.0))


# --------------------------------------------------------------------------- the world


class PybulletWorld(ScriptedObject):
    """pybullet physics world with the ``sim_backend.base.World`` interface."""

    control_every = 2  # physics steps between robot pose reads, re-basing and re-aiming
    rebase_distance = 1e-3  # m: a diff robot's F offset (its turning pivot error) is kept below
    reaim_angle = 5e-3  # rad: an omni robot's targets are re-aimed past this heading change

    def __init__(
        self,
        cfg: FleetConfig,
        gui: bool = False,
        *,
        tyre_grip: float = 1.0,
        tracker_gain: float = 10.0,
    ):
        """Build the world from ``cfg``.

        ``tyre_grip`` (dimensionless) bounds a differential robot's lateral resistance to
        ``tyre_grip`` · m · g; ``tracker_gain`` (1/s) is the live object's velocity-tracking gain
        (its force is bounded by ``object.motion.max_force`` anyway).
        """
        self.cfg = cfg
        self.dt = cfg.sim.timestep
        self._steps = 0
        self._cid = pb.connect(pb.GUI if gui else pb.DIRECT)
        if self._cid < 0:
            raise RuntimeError("pybullet: cannot connect (is a GUI already open?)")
        self._closed = False
        c = self._cid
        pb.setGravity(0, 0, -GRAVITY, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=c)
        self._tyre_grip = tyre_grip
        self._gain = tracker_gain
        self._build_static()
        self._build_object()
        self._build_robots()
        self._drive_target: tuple[float, float, float] | None = None
        self._script = ObjectScript(cfg.object.motion, cfg.object.start)
        self._give_up = GiveUp.for_motion(cfg.object.motion)
        if not self._give_up.alive:  # inert: floor friction from the start
            mu = cfg.object.floor_friction * cfg.sim.object_friction_scale
            self._set_floor_friction(mu)
        self._read_state()

    # ------------------------------------------------------------------ construction

    def _build_static(self) -> None:
        c = self._cid
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self._floor = pb.createMultiBody(0, plane, physicsClientId=c)
        pb.changeDynamics(self._floor, -1, lateralFriction=1.0, physicsClientId=c)
        self._static: list[int] = []
        if self.cfg.world.walls:
            (x0, y0), (x1, y1) = self.cfg.world.bounds
            t = WALL_THICKNESS
            boxes = [
                ((x0 - t / 2, (y0 + y1) / 2), (t / 2, (y1 - y0) / 2 + t)),
                ((x1 + t / 2, (y0 + y1) / 2), (t / 2, (y1 - y0) / 2 + t)),
                (((x0 + x1) / 2, y0 - t / 2), ((x1 - x0) / 2 + t, t / 2)),
                (((x0 + x1) / 2, y1 + t / 2), ((x1 - x0) / 2 + t, t / 2)),
            ]
            for (cx, cy), (hx, hy) in boxes:
                shape = pb.createCollisionShape(
                    pb.GEOM_BOX, halfExtents=[hx, hy, WALL_HEIGHT / 2], physicsClientId=c
                )
                vis = self._visual_box(hx, hy, WALL_HEIGHT / 2, (0.6, 0.6, 0.6, 1))
                self._static.append(
                    pb.createMultiBody(
                        0, shape, vis, basePosition=[cx, cy, WALL_HEIGHT / 2], physicsClientId=c
                    )
                )
        for ob in self.cfg.obstacles:
            for piece in convex_pieces(np.asarray(ob.polygon)):
                # Planar world: anything lower than a robot would still block it.
                height = max(ob.height, ROBOT_LIFT + ROBOT_HEIGHT)
                shape, vis = self._prism(piece, 0.0, height, (0.4, 0.4, 0.45, 1))
                self._static.append(pb.createMultiBody(0, shape, vis, physicsClientId=c))
        for body in self._static:
            pb.changeDynamics(body, -1, lateralFriction=STATIC_FRICTION, physicsClientId=c)

    def _visual_box(self, hx: float, hy: float, hz: float, rgba: tuple) -> int:
        return pb.createVisualShape(
            pb.GEOM_BOX, halfExtents=[hx, hy, hz], rgbaColor=rgba, physicsClientId=self._cid
        )

    def _prism(self, piece: np.ndarray, z0: float, height: float, rgba: tuple) -> tuple[int, int]:
        verts = [[float(x), float(y), z] for z in (z0, z0 + height) for x, y in piece]
        shape = pb.createCollisionShape(pb.GEOM_MESH, vertices=verts, physicsClientId=self._cid)
        vis = -1
        # Visual meshes need triangle indices: a fan per cap and two triangles per side.
        n = len(piece)
        idx: list[int] = []
        for k in range(1, n - 1):
            idx += [0, k + 1, k, n, n + k, n + k + 1]
        for k in range(n):
            j = (k + 1) % n
            idx += [k, j, n + j, k, n + j, n + k]
        vis = pb.createVisualShape(
            pb.GEOM_MESH, vertices=verts, indices=idx, rgbaColor=rgba, physicsClientId=self._cid
        )
        return shape, vis

    def _build_object(self) -> None:
        c = self._cid
        o = self.cfg.object
        poly = self.cfg.object_polygon()
        self._poly = poly
        self._obstacles = self.cfg.obstacle_polygons()
        m = o.mass * self.cfg.sim.object_mass_scale  # the true mass (sim.object_mass_scale)
        h = max(o.height, ROBOT_HEIGHT)  # planar world: robots must not pass over a flat object
        pieces = convex_pieces(poly)
        self._pieces = pieces
        centroid = geometry.centroid(poly)
        rbar = mean_radius(poly)
        self._rbar = rbar
        skids = [
            centroid + rbar * np.array([math.cos(a), math.sin(a)])
            for a in (math.pi / 2, math.pi / 2 + 2 * math.pi / 3, math.pi / 2 + 4 * math.pi / 3)
        ]
        z_mid = OBJECT_LIFT + h / 2
        shapes, visuals, com_local, masses = [], [], [], []
        for piece in pieces:
            s, v = self._prism(piece, OBJECT_LIFT, h, (0.85, 0.45, 0.1, 1))
            shapes.append(s)
            visuals.append(v)
            com_local.append([*geometry.centroid(piece), z_mid])
        for q in skids:
            shapes.append(
                pb.createCollisionShape(
                    pb.GEOM_SPHERE,
                    radius=SKID_RADIUS,
                    collisionFramePosition=[float(q[0]), float(q[1]), SKID_RADIUS],
                    physicsClientId=c,
                )
            )
            visuals.append(-1)
            com_local.append([float(q[0]), float(q[1]), SKID_RADIUS])
        n_links = len(shapes) - 1
        light = _LIGHT * m
        masses = [light] * n_links
        base_mass = m - light * n_links
        # The base carries the mass; its centre is placed so the composite sits on the centroid.
        link_moment = sum(light * np.asarray(cl[:2]) for cl in com_local[1:])
        com = centroid + np.asarray(self.cfg.sim.object_com_offset, float)  # the true COM
        base_com = (m * com - link_moment) / base_mass
        self._base_com = base_com
        izz = geometry.polar_moment_per_mass(poly) * m
        self._izz = izz
        self._radius_gyration = math.sqrt(geometry.polar_moment_per_mass(poly))
        x, y, th = o.start
        self._obj = pb.createMultiBody(
            baseMass=base_mass,
            baseCollisionShapeIndex=shapes[0],
            baseVisualShapeIndex=visuals[0],
            basePosition=[x, y, 0.0],
            baseOrientation=quat_of(th),
            baseInertialFramePosition=[float(base_com[0]), float(base_com[1]), z_mid],
            linkMasses=masses,
            linkCollisionShapeIndices=shapes[1:],
            linkVisualShapeIndices=visuals[1:],
            linkPositions=[[0, 0, 0]] * n_links,
            linkOrientations=[[0, 0, 0, 1]] * n_links,
            linkInertialFramePositions=com_local[1:],
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * n_links,
            linkParentIndices=[0] * n_links,
            linkJointTypes=[pb.JOINT_FIXED] * n_links,
            linkJointAxis=[[0, 0, 1]] * n_links,
            physicsClientId=c,
        )
        # Tilting inertia of a slab; only izz matters for planar motion.
        tilt = izz / 2 + base_mass * h * h / 12
        pb.changeDynamics(
            self._obj,
            -1,
            localInertiaDiagonal=[tilt, tilt, izz],
            linearDamping=0.0,
            angularDamping=0.0,
            physicsClientId=c,
        )
        self._piece_links = [-1] + list(range(len(pieces) - 1))
        self._skid_links = list(range(len(pieces) - 1, n_links))
        for link in self._piece_links:
            pb.changeDynamics(self._obj, link, lateralFriction=1.0, physicsClientId=c)
        self._set_floor_friction(0.0)

    def _set_floor_friction(self, mu: float) -> None:
        for link in self._skid_links:
            pb.changeDynamics(
                self._obj,
                link,
                lateralFriction=mu,
                spinningFriction=0.0,
                rollingFriction=0.0,
                physicsClientId=self._cid,
            )

    def _build_robots(self) -> None:
        c = self._cid
        cfg = self.cfg
        self._ids = cfg.robot_ids
        self._index = {rid: i for i, rid in enumerate(self._ids)}
        self._diff = np.array([r.kind == "diff" for r in cfg.robots])
        self._radius = np.array([r.radius for r in cfg.robots])
        self._bodies: list[int] = []
        self._motor_limits: list[list[float]] = []
        z = ROBOT_LIFT + ROBOT_HEIGHT / 2
        for r in cfg.robots:
            diff = r.kind == "diff"
            shape = pb.createCollisionShape(
                pb.GEOM_CYLINDER, radius=r.radius, height=ROBOT_HEIGHT, physicsClientId=c
            )
            rgba = (0.2, 0.7, 0.3, 1) if diff else (0.2, 0.4, 0.9, 1)
            vis = pb.createVisualShape(
                pb.GEOM_CYLINDER,
                radius=r.radius,
                length=ROBOT_HEIGHT,
                rgbaColor=rgba,
                physicsClientId=c,
            )
            # omni: X, Y (world), Z;  diff: X, Y (world, tyre locks), Z, F (body forward).
            types = [pb.JOINT_PRISMATIC, pb.JOINT_PRISMATIC, pb.JOINT_REVOLUTE]
            axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
            if diff:
                types.append(pb.JOINT_PRISMATIC)
                axes.append([1, 0, 0])
            n = len(types)
            chain = _CHAIN * r.mass
            body = pb.createMultiBody(
                baseMass=0,
                basePosition=[0, 0, z],
                linkMasses=[chain] * (n - 1) + [r.mass],
                linkCollisionShapeIndices=[-1] * (n - 1) + [shape],
                linkVisualShapeIndices=[-1] * (n - 1) + [vis],
                linkPositions=[[0, 0, 0]] * n,
                linkOrientations=[[0, 0, 0, 1]] * n,
                linkInertialFramePositions=[[0, 0, 0]] * n,
                linkInertialFrameOrientations=[[0, 0, 0, 1]] * n,
                linkParentIndices=list(range(n)),
                linkJointTypes=types,
                linkJointAxis=axes,
                physicsClientId=c,
            )
            x, y, th = r.start
            pb.resetJointStatesMultiDof(
                body, list(range(n)), [[x], [y], [th]] + [[0.0]] * (n - 3), physicsClientId=c
            )
            for j in range(n):
                pb.changeDynamics(body, j, linearDamping=0.0, angularDamping=0.0, physicsClientId=c)
            pb.changeDynamics(
                body, n - 1, lateralFriction=self.cfg.object.contact_friction, physicsClientId=c
            )
            torque = r.max_force * r.radius
            if diff:
                grip = self._tyre_grip * r.mass * GRAVITY
                self._motor_limits.append([grip, grip, torque, r.max_force])
            else:
                self._motor_limits.append([r.max_force, r.max_force, torque])
            self._bodies.append(body)
        n = len(self._ids)
        self._cmd = np.zeros((n, 3))
        self._pose = np.array([r.start for r in cfg.robots], dtype=float)
        self._vel = np.zeros((n, 3))
        self._aimed = self._pose[:, 2].copy()  # heading an omni robot's targets were aimed at
        self._offset = np.zeros(n)  # a diff robot's forward offset from its chain's X/Y point
        for i in range(n):
            self._apply_command(i)

    def _apply_command(self, i: int) -> None:
        """Set robot i's motors from its command (omni targets aimed at its current heading)."""
        vx, vy, wz = self._cmd[i]
        if self._diff[i]:
            joints, targets = [0, 1, 2, 3], [0.0, 0.0, wz, vx]
        else:
            th = self._pose[i, 2]
            cs, sn = math.cos(th), math.sin(th)
            joints, targets = [0, 1, 2], [cs * vx - sn * vy, sn * vx + cs * vy, wz]
            self._aimed[i] = th
        pb.setJointMotorControlArray(
            self._bodies[i],
            joints,
            pb.VELOCITY_CONTROL,
            targetVelocities=targets,
            forces=self._motor_limits[i],
            physicsClientId=self._cid,
        )

    # ------------------------------------------------------------------ state

    def _read_robots(self, rebase: bool) -> None:
        """Cache every robot's pose and velocity; re-base diff chains and re-aim omni targets.

        Re-basing folds a differential robot's forward offset F into its X/Y joints so that its
        heading joint turns it about its own centre (a joint reset also resets the motor targets,
        so the command is re-applied). An omni robot's world-frame targets are re-aimed when its
        heading has changed.
        """
        c = self._cid
        for i, body in enumerate(self._bodies):
            if self._diff[i]:
                js = pb.getJointStates(body, [0, 1, 2, 3], physicsClientId=c)
                x, vx = js[0][0], js[0][1]
                y, vy = js[1][0], js[1][1]
                th, wz = js[2][0], js[2][1]
                f, vf = js[3][0], js[3][1]
                cs, sn = math.cos(th), math.sin(th)
                px, py = x + cs * f, y + sn * f
                self._pose[i] = (px, py, wrap_angle(th))
                self._vel[i] = (vx + cs * vf, vy + sn * vf, wz)
                self._offset[i] = f
                if rebase and abs(f) > self.rebase_distance:
                    pb.resetJointStatesMultiDof(
                        body, [0, 1, 3], [[px], [py], [0.0]], [[vx], [vy], [vf]], physicsClientId=c
                    )
                    self._offset[i] = 0.0
                    self._apply_command(i)
            else:
                js = pb.getJointStates(body, [0, 1, 2], physicsClientId=c)
                th = js[2][0]
                self._pose[i] = (js[0][0], js[1][0], wrap_angle(th))
                self._vel[i] = (js[0][1], js[1][1], js[2][1])
                if rebase and abs(th - self._aimed[i]) > self.reaim_angle:
                    self._apply_command(i)

    def _read_object(self) -> None:
        c = self._cid
        pos, quat = pb.getBasePositionAndOrientation(self._obj, physicsClientId=c)
        lin, ang = pb.getBaseVelocity(self._obj, physicsClientId=c)
        th = yaw_of(quat)
        cs, sn = math.cos(th), math.sin(th)
        bx, by = self._base_com
        # The base's centre of mass sits on the composite one (the light links are compensated).
        ox = pos[0] - (cs * bx - sn * by)
        oy = pos[1] - (sn * bx + cs * by)
        w = ang[2]
        self._com = pos
        self._obj_state = (ox, oy, th, lin[0] - w * (oy - pos[1]), lin[1] + w * (ox - pos[0]), w)
        self._obj_com_vel = (lin[0], lin[1], w)

    def _read_state(self) -> None:
        self._read_robots(rebase=True)
        self._read_object()

    def _update_drive_target(self) -> None:
        """Centre-of-mass velocity target (m/s, m/s, rad/s) of the live object from its script."""
        ox, oy, th = self._obj_state[:3]
        v = self._script.target_velocity(self.t, np.array([ox, oy, th]), self._pose[:, :2])
        rx, ry = self._com[0] - ox, self._com[1] - oy
        self._drive_target = (float(v[0] - v[2] * ry), float(v[1] + v[2] * rx), float(v[2]))

    def _drive_object(self) -> None:
        """Apply the live object's bounded tracking force and torque for this step."""
        tx, ty, tw = self._drive_target
        vx, vy, w = self._obj_com_vel
        k = self.cfg.object.mass * self._gain
        fx, fy = k * (tx - vx), k * (ty - vy)
        fmax = self.cfg.object.motion.max_force
        norm = math.hypot(fx, fy)
        if norm > fmax:
            fx, fy = fx * fmax / norm, fy * fmax / norm
        tmax = fmax * self._radius_gyration
        torque = min(tmax, max(-tmax, self._izz * self._gain * (tw - w)))
        c = self._cid
        pb.applyExternalForce(
            self._obj, -1, [fx, fy, 0.0], self._com, pb.WORLD_FRAME, physicsClientId=c
        )
        pb.applyExternalTorque(self._obj, -1, [0.0, 0.0, torque], pb.WORLD_FRAME, physicsClientId=c)

    # ------------------------------------------------------------------ the World interface

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return self._steps * self.dt

    @property
    def robot_ids(self) -> tuple[str, ...]:
        return self._ids

    def set_command(self, robot_id: str, vx: float, vy: float, wz: float) -> None:
        """Body-frame velocity target (m/s, m/s, rad/s); a differential robot ignores vy."""
        i = self._index[robot_id]
        cmd = (float(vx), float(vy), float(wz))
        if tuple(self._cmd[i]) != cmd:
            self._cmd[i] = cmd
            self._apply_command(i)

    def step(self, duration: float) -> None:
        """Advance by ``duration`` seconds (rounded to whole physics steps, at least one)."""
        n = max(1, int(round(duration / self.dt)))
        for _ in range(n):
            alive = self._give_up.alive
            if alive:
                if self._steps % self.control_every == 0 or self._drive_target is None:
                    self._update_drive_target()
                self._drive_object()
            pb.stepSimulation(physicsClientId=self._cid)
            self._steps += 1
            self._read_object()
            if alive and not self._give_up.update(
                self.t, self.dt, np.asarray(self._drive_target), np.asarray(self._obj_com_vel)
            ):
                # it fought the hold (or the wall) long enough: drive off, floor friction on
                mu = self.cfg.object.floor_friction * self.cfg.sim.object_friction_scale
                self._set_floor_friction(mu)
            if self._steps % self.control_every == 0:
                self._read_robots(rebase=True)
        if self._steps % self.control_every != 0:
            self._read_robots(rebase=True)

    def robot_pose(self, robot_id: str) -> np.ndarray:
        """True (x, y, theta) of a robot (m, m, rad)."""
        return self._pose[self._index[robot_id]].copy()

    def robot_velocity(self, robot_id: str) -> np.ndarray:
        """True world-frame (vx, vy, wz) of a robot (m/s, m/s, rad/s)."""
        return self._vel[self._index[robot_id]].copy()

    def object_pose(self) -> np.ndarray:
        """True (x, y, theta) of the object's polygon frame (m, m, rad)."""
        return np.array(self._obj_state[:3])

    def object_velocity(self) -> np.ndarray:
        """True world-frame (vx, vy, wz) of the object frame's origin (m/s, m/s, rad/s)."""
        return np.array(self._obj_state[3:])

    def check(self) -> WorldCheck:
        """Safety figures of the current true state."""
        return check_discs(
            self._ids,
            self._pose[:, :2],
            self._radius,
            self._poly,
            self.object_pose(),
            self._obstacles,
            self.cfg.bounds_array(),
        )

    def contact_forces(self) -> dict[str, float]:
        """The normal force (N) each robot presses on the object with now (truth, from the
        solver's contact points; robots not touching it are left out)."""
        out: dict[str, float] = {}
        for rid, body in zip(self._ids, self._bodies, strict=True):
            pts = pb.getContactPoints(bodyA=body, bodyB=self._obj, physicsClientId=self._cid)
            total = float(sum(p[9] for p in pts))
            if total > 0.0:
                out[rid] = total
        return out

    def apply_object_force(self, force: tuple[float, float], at: tuple[float, float] | None = None):
        """Push the object for the next step with a world-frame force (N) at a world point.

        For tests and disturbances; ``at`` defaults to the centre of mass. Cleared by each step.
        """
        p = list(self._com) if at is None else [at[0], at[1], self._com[2]]
        pb.applyExternalForce(
            self._obj, -1, [force[0], force[1], 0.0], p, pb.WORLD_FRAME, physicsClientId=self._cid
        )

    def apply_robot_force(self, robot_id: str, force: tuple[float, float]) -> None:
        """Push a robot's body for the next step with a world-frame force (N) (tests)."""
        i = self._index[robot_id]
        link = 3 if self._diff[i] else 2
        pos = pb.getLinkState(self._bodies[i], link, physicsClientId=self._cid)[0]
        pb.applyExternalForce(
            self._bodies[i],
            link,
            [force[0], force[1], 0.0],
            list(pos),
            pb.WORLD_FRAME,
            physicsClientId=self._cid,
        )

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            pb.disconnect(physicsClientId=self._cid)

    def __enter__(self) -> PybulletWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
