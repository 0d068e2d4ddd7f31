"""The kinematic model the transport planners roll action matrices out on, and its energy.

Pure: arrays in, arrays out; the only solver is the contact-force LP
(:mod:`controller.planning.contact_lp`).

**The object** (:class:`ObjectModel`, built once per mission): its polygon (object frame, CCW),
mass, floor friction μ, contact friction μ_c, area centroid c, mean radius r̄ (the floor-friction
limit surface of :func:`controller.planning.contact_lp.required_wrench`), boundary nodes every
``node_spacing`` along each edge (outward normals, arc length, whether a robot disc fits there:
not in a concave notch narrower than the robot), the nodes the relocation scan visits (every
``relocation_spacing``), and the *lane*: the convex hull grown by 3·r_max + margin, outside any
robot in contact, along which relocating robots travel.

**The route** (:class:`RoutePath`): the path of the centroid along the route's waypoints, with
the heading scaled by r̄ as a third coordinate, so that "pose arc length" s counts metres driven
plus r̄ × radians turned (an in-place turn of the route is progress too). Deviation is the
centroid's (x, y) distance from the path.

**One interval** of length dt (:meth:`Rollout.step`), from the state at its start:

1. Effective actions: a travelling relocator keeps travelling (its V entry is ignored); a robot
   without contact can only relocate or idle (anything else is idle).
2. A robot starting to relocate leaves its contact; its target is the relocation scan's node
   (chosen once per plan from the plan's starting configuration, Vass Fig. 5); its path runs
   out to the lane, along the lane the shorter way, and in to the target (object frame). A
   robot told to relocate while it sits on its target pushes there (a relocation ends in a
   push at the point the scan chose for pushing).
3. The commanded twist: toward the *carrot*, the route point max(``lookahead``, speed·dt)
   (pose arc) past the centroid's match on the route but never past the subgoal, at
   ``speed`` in pose-arc metres per second (exactly onto the carrot when it is closer than
   speed·dt); scaled down so that no attached
   robot (push, follow, slide) must move faster than its max_speed (sliders: minus the slide).
4. The LP: the pushers (action push, in contact) must make the limit-surface wrench of that
   twist within their max_force. Under the error model (``TransportParams.pose_error``,
   ``com_error``) a push at a node the plan moved the robot to within the motion error of a
   vertex counts for nothing, and the wrench must be made for either extreme of the centre of
   mass's offset (:func:`robust_wrenches`). Feasible: the object moves by the twist for dt
   (heading by ω·dt, centroid by v·dt). Infeasible: it stays where it is (Coulomb friction
   does not depend on speed, so a slower push needs the same forces) and the interval counts
   as infeasible.
5. Robots: push and follow keep their contact point (they move with the object); sliders move
   ``slide_speed``·dt along the boundary over nodes where they fit (they stop at a notch);
   idle robots stay put in the world: they lose contact if the object left them by more than
   ``contact_tolerance``, and are hit if it moved into them by more than that; travelling
   robots advance max_speed·dt along their path (object frame, carried along) and attach on
   arrival.
6. Collisions at the interval's end: two robot discs overlapping (under the error model:
   nearer than twice the motion error, unless the pair started the plan nearer), the object
   entering a robot, a robot or the object touching an obstacle, a robot leaving the bounds.

**Energy** (Vass Eq. 3 with two route terms): E = K_c·(intervals with a collision) +
K_e·(intervals whose LP is infeasible) + K_f·Σ|f| (N, every robot every interval) +
K_g·(changes of a robot's action from one interval to the next, the first against the action
it executed last) + K_d·Σ deviation (m, at each interval's end) − K_p·progress (pose arc, m).

The rollout is incremental for the annealer: changing V[j, i] re-rolls from interval j and stops
as soon as an interval ends in the same state as before (the rest is then unchanged). LP answers
are cached by (twist, pushers) within a rollout object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from controller import geometry
from controller.planning.contact_lp import (
    ContactForceLP,
    LPResult,
    required_wrench,
)
from controller.planning.transport_types import (
    ATTACHED,
    FOLLOW,
    IDLE,
    PUSH,
    RELOCATE,
    SLIDE_LEFT,
    SLIDE_RIGHT,
    Energy,
    FloatArray,
    IntArray,
    TransportParams,
    TransportState,
    action_code,
)

_TOL = 1e-9


# --------------------------------------------------------------------------- the object


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """The carried object as the planners see it (see the module docstring). Object frame."""

    polygon: FloatArray
    mass: float
    floor_friction: float
    contact_friction: float
    centroid: FloatArray
    mean_radius: float
    robot_radius: float
    node_spacing: float
    nodes: FloatArray  # (M, 2) boundary points, CCW by arc length
    normals: FloatArray  # (M, 2) outward unit normals
    arc: FloatArray  # (M,) arc length from vertex 0 (m)
    fit: NDArray[np.bool_]  # (M,) a robot disc of robot_radius fits at the node
    # (M,) a push there counts: every node without an error model; with one, the fit nodes at
    # least ``push_margin`` from every vertex (the robot pushes the face whatever its error)
    pushable: NDArray[np.bool_]
    next_ccw: IntArray  # (M,) the next node counter-clockwise if a robot can slide there
    next_cw: IntArray
    relocation_nodes: IntArray  # (R,) fit nodes the relocation scan visits
    lane: FloatArray  # (L, 2) closed CCW polyline (last point == first)
    lane_arc: FloatArray  # (L,) cumulative length along the lane

    @classmethod
    def build(
        cls,
        polygon: ArrayLike,
        mass: float,
        floor_friction: float,
        contact_friction: float,
        robot_radius: float,
        node_spacing: float = 0.01,
        relocation_spacing: float = 0.1,
        lane_margin: float = 0.05,
        push_margin: float = 0.0,
    ) -> ObjectModel:
        """Precompute everything per object; ``robot_radius``: the fleet's largest (m);
        ``push_margin``: m from a vertex within which a robot's push does not count (the
        error model's motion error: the robot may be pushing the corner, or nothing)."""
        poly = geometry.ensure_ccw(np.asarray(polygon, float))
        pts, nrm, arc = _boundary_nodes(poly, node_spacing)
        fit = ~geometry.discs_hit_polygon(pts + (robot_radius + 1e-3) * nrm, robot_radius, poly)
        pushable = np.ones(len(pts), bool)
        if push_margin > 0:
            pushable = fit & (geometry.vertex_distance(pts, poly) >= push_margin - 1e-12)
        m = len(pts)
        ccw = np.roll(np.arange(m), -1)
        cw = np.roll(np.arange(m), 1)
        next_ccw = np.where(fit & fit[ccw], ccw, np.arange(m))
        next_cw = np.where(fit & fit[cw], cw, np.arange(m))
        bins = np.floor(arc / relocation_spacing).astype(int)
        first = np.concatenate([[True], bins[1:] != bins[:-1]])
        if push_margin > 0:  # the first pushable node of each bin (a bin's first may not be)
            keep = np.flatnonzero(pushable)
            first = np.zeros(len(pts), bool)
            first[keep[np.concatenate([[True], bins[keep][1:] != bins[keep][:-1]])]] = True
        lane = _lane(poly, 3.0 * robot_radius + lane_margin)
        return cls(
            polygon=poly,
            mass=float(mass),
            floor_friction=float(floor_friction),
            contact_friction=float(contact_friction),
            centroid=geometry.centroid(poly),
            mean_radius=geometry.mean_radius(poly),
            robot_radius=float(robot_radius),
            node_spacing=float(node_spacing),
            nodes=pts,
            normals=nrm,
            arc=arc,
            fit=fit,
            pushable=pushable,
            next_ccw=next_ccw,
            next_cw=next_cw,
            relocation_nodes=np.flatnonzero(first & fit & pushable),
            lane=lane,
            lane_arc=_cumulative(lane),
        )

    def snap(self, point: ArrayLike, inward_normal: ArrayLike | None = None) -> int:
        """The boundary node for a contact (object frame): nearest, ties broken by the normal."""
        p = np.asarray(point, float)
        cost = np.linalg.norm(self.nodes - p, axis=1)
        if inward_normal is not None:
            n = np.asarray(inward_normal, float)
            cost = cost + self.node_spacing * (1.0 + self.normals @ n)
        return int(np.argmin(cost))

    def centre(self, node: int, radius: float) -> FloatArray:
        """Object-frame centre of a robot of ``radius`` touching the node."""
        return self.nodes[node] + radius * self.normals[node]


def robust_wrenches(wrench: ArrayLike, com_error: float) -> list[FloatArray]:
    """The wrenches (about the centroid) a set must make for the floor friction of ``wrench``
    to be overcome wherever the centre of mass is within ±``com_error`` m per axis of the
    centroid: friction acting at an offset c turns the torque by c × F, at most
    com_error·(|Fx| + |Fy|) either way; the set of wrenches a set of contacts can make is
    convex, so the two extremes cover every offset between. Without an error, ``wrench``."""
    w = np.asarray(wrench, float)
    dt = com_error * (abs(w[0]) + abs(w[1]))
    if dt <= 0:
        return [w]
    return [w + [0.0, 0.0, dt], w - [0.0, 0.0, dt]]


def _boundary_nodes(poly: FloatArray, spacing: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    a, e = geometry.edges(poly)
    lengths = np.linalg.norm(e, axis=1)
    normals = geometry.outward_normals(poly)
    start = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    pts, nrm, arc = [], [], []
    for k in range(len(poly)):
        m = max(1, int(np.floor(lengths[k] / spacing + 1e-9)))
        s = (np.arange(m) + 0.5) / m
        pts.append(a[k] + s[:, None] * e[k])
        nrm.append(np.repeat(normals[k][None], m, axis=0))
        arc.append(start[k] + s * lengths[k])
    return np.concatenate(pts), np.concatenate(nrm), np.concatenate(arc)


def _lane(poly: FloatArray, offset: float) -> FloatArray:
    hull = shapely.Polygon(geometry.convex_hull(poly)).buffer(offset, quad_segs=4)
    ring = np.asarray(hull.exterior.coords, float)[:-1]
    ring = geometry.ensure_ccw(ring)
    return np.vstack([ring, ring[:1]])


def _cumulative(path: FloatArray) -> FloatArray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])


def lane_point(model: ObjectModel, s: float) -> FloatArray:
    """The lane point at arc length s (wrapped)."""
    total = model.lane_arc[-1]
    s = s % total
    k = int(np.searchsorted(model.lane_arc, s, side="right") - 1)
    k = min(k, len(model.lane) - 2)
    seg = model.lane_arc[k + 1] - model.lane_arc[k]
    t = 0.0 if seg <= 0 else (s - model.lane_arc[k]) / seg
    return model.lane[k] + t * (model.lane[k + 1] - model.lane[k])


def lane_project(model: ObjectModel, p: ArrayLike) -> float:
    """Arc length of the lane point nearest to p (object frame)."""
    a, b = model.lane[:-1], model.lane[1:]
    d, closest = geometry.point_segment_distance(np.asarray(p, float)[None], a, b)
    k = int(np.argmin(d[0]))
    return float(model.lane_arc[k] + np.linalg.norm(closest[0, k] - a[k]))


def relocation_path(model: ObjectModel, start: ArrayLike, end: ArrayLike) -> FloatArray:
    """Object-frame polyline from a robot centre ``start`` out to the lane, along the lane the
    shorter way round, and in to the centre ``end``."""
    s0, s1 = lane_project(model, start), lane_project(model, end)
    total = float(model.lane_arc[-1])
    fwd = (s1 - s0) % total
    inner = model.lane_arc[1:-1]
    if fwd <= total - fwd:
        mid = inner[((inner - s0) % total) < fwd]
        mid = mid[np.argsort((mid - s0) % total)]
    else:
        mid = inner[((s0 - inner) % total) < total - fwd]
        mid = mid[np.argsort((s0 - mid) % total)]
    pts = [np.asarray(start, float), lane_point(model, s0)]
    pts += [lane_point(model, s) for s in mid]
    pts += [lane_point(model, s1), np.asarray(end, float)]
    return np.vstack(pts)


def _along(path: FloatArray, cum: FloatArray, d: float) -> FloatArray:
    k = int(np.searchsorted(cum, d, side="right") - 1)
    k = min(max(k, 0), len(path) - 2)
    seg = cum[k + 1] - cum[k]
    t = 0.0 if seg <= 0 else min(1.0, (d - cum[k]) / seg)
    return path[k] + t * (path[k + 1] - path[k])


# --------------------------------------------------------------------------- the route


class RoutePath:
    """The centroid's route in (x, y, r̄·θ) with pose arc length s. Queries look at a window
    (:meth:`focus`: from just behind the plan's start to the subgoal)."""

    def __init__(self, waypoints: ArrayLike, subgoal: int, model: ObjectModel):
        wp = np.atleast_2d(np.asarray(waypoints, float))
        if len(wp) == 0 or wp.shape[1] != 3:
            raise ValueError("route.waypoints: expected (k >= 1, 3) poses")
        c, rbar = model.centroid, model.mean_radius
        th = np.unwrap(wp[:, 2])
        cx = wp[:, 0] + np.cos(th) * c[0] - np.sin(th) * c[1]
        cy = wp[:, 1] + np.sin(th) * c[0] + np.cos(th) * c[1]
        pts = np.column_stack([cx, cy, rbar * th])
        if len(pts) == 1:
            pts = np.vstack([pts, pts])
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        self.rbar = rbar
        self.points = pts
        self.arc = np.concatenate([[0.0], np.cumsum(seg)])
        sub = (len(wp) - 1) if subgoal < 0 else min(int(subgoal), len(wp) - 1)
        self.subgoal_index = sub
        self.s_subgoal = float(self.arc[sub])
        self.length = float(self.arc[-1])
        self._window(0, len(pts) - 1)

    def _window(self, lo: int, hi: int) -> None:
        self._lo, self._hi = lo, hi
        self._a = self.points[lo:hi]
        self._e = self.points[lo + 1 : hi + 1] - self._a
        self._den = np.maximum(np.einsum("ij,ij->i", self._e, self._e), 1e-300)
        self._arc = self.arc[lo:hi]
        self._len = self.arc[lo + 1 : hi + 1] - self._arc

    def focus(self, q: ArrayLike) -> None:
        """Restrict the queries to the route from just behind q = (cx, cy, r̄·θ) to the
        subgoal (the part a local plan can reach)."""
        self._window(0, len(self.points) - 1)
        i0 = self._lo + self._match(np.asarray(q, float))[0]
        lo = max(0, min(i0, self.subgoal_index) - 2)
        self._window(lo, max(min(len(self.points) - 1, self.subgoal_index + 1), lo + 1))

    def _match(self, q: FloatArray) -> tuple[int, float]:
        t = np.clip(((q - self._a) * self._e).sum(1) / self._den, 0.0, 1.0)
        d = self._a + t[:, None] * self._e - q
        k = int(np.argmin((d * d).sum(1)))
        return k, float(t[k])

    def unwrap_heading(self, theta: float, xy: ArrayLike) -> float:
        """θ (rad) unwrapped next to the route's heading at its (x, y)-nearest waypoint."""
        i = int(np.argmin(np.linalg.norm(self.points[:, :2] - np.asarray(xy, float), axis=1)))
        ref = self.points[i, 2] / self.rbar
        return float(ref + geometry.wrap_angle(theta - ref))

    def locate(self, q: FloatArray) -> tuple[float, float, float]:
        """For q = (cx, cy, r̄·θ): its match on the route (the nearest point in these
        coordinates) as (pose arc length s m, (x, y) distance from the match m, side: +1 when
        the centroid is left of the travel direction, −1 right)."""
        k, t = self._match(q)
        s = float(self._arc[k] + t * self._len[k])
        e = self._e[k]
        off = q[:2] - (self._a[k, :2] + t * e[:2])
        dev = math.hypot(off[0], off[1])
        if e[0] == 0.0 and e[1] == 0.0:  # an in-place turn: side from the route's direction
            e = self.tangent(q)
        side = 1.0 if e[0] * off[1] - e[1] * off[0] >= 0 else -1.0
        return s, dev, side

    def project(self, q: FloatArray) -> float:
        """Pose arc length s (m) of q's match on the route."""
        k, t = self._match(np.asarray(q, float))
        return float(self._arc[k] + t * self._len[k])

    def tangent(self, q: FloatArray) -> FloatArray:
        """Unit (x, y) travel direction of the route at q's match (the nearest moving segment
        if q matches an in-place turn)."""
        i = self._lo + self._match(np.asarray(q, float))[0]
        for k in list(range(i, self._hi)) + list(range(i - 1, self._lo - 1, -1)):
            e = self.points[k + 1, :2] - self.points[k, :2]
            n = float(np.linalg.norm(e))
            if n > 1e-9:
                return e / n
        return np.array([1.0, 0.0])

    def at(self, s: float) -> FloatArray:
        """The route point (cx, cy, r̄·θ) at pose arc length s (clipped to the route)."""
        s = min(max(s, 0.0), self.length)
        k = int(np.searchsorted(self.arc, s, side="right") - 1)
        k = min(max(k, 0), len(self.points) - 2)
        seg = self.arc[k + 1] - self.arc[k]
        t = 0.0 if seg <= 0 else (s - self.arc[k]) / seg
        return self.points[k] + t * (self.points[k + 1] - self.points[k])


# --------------------------------------------------------------------------- the relocation scan


def relocation_scan(
    model: ObjectModel,
    contacts: IntArray,
    max_force: FloatArray,
    radii: FloatArray,
    candidate_radius: float,
    candidate_force: float,
    wrench: FloatArray,
    lp: ContactForceLP,
    candidates: IntArray | None = None,
    taken: FloatArray | None = None,
) -> tuple[int, FloatArray]:
    """Vass §4 / Fig. 5: the contact node for a relocating robot that minimises the summed
    normal forces of all contacts (the others, all pushing, plus it) making ``wrench``.

    contacts: (n,) nodes of the other robots in contact; max_force, radii: theirs (N, m);
    candidate_radius, candidate_force: the relocating robot's; wrench: (3,) object frame about
    the centroid (N, N, N·m). Nodes where its disc would overlap another robot are skipped, and
    nodes within a robot diameter of a ``taken`` centre (object frame: where other relocating
    robots are going).
    Returns (node, values) with values[k] the objective at ``candidates[k]`` (N; inf where the
    LP is infeasible or the node is taken). If no node is feasible, the node whose push points
    most along the needed force wins (its value stays inf).
    """
    cand = model.relocation_nodes if candidates is None else np.asarray(candidates, int)
    c = model.centroid
    others = model.nodes[contacts] - c
    other_n = -model.normals[contacts]
    centres = model.nodes[contacts] + radii[:, None] * model.normals[contacts]
    values = np.full(len(cand), np.inf)
    fmax = np.concatenate([max_force, [candidate_force]])
    active = np.ones(len(contacts) + 1, bool)
    for k, node in enumerate(cand):
        centre = model.centre(int(node), candidate_radius)
        if len(centres) and np.any(
            np.linalg.norm(centres - centre, axis=1) < radii + candidate_radius - 1e-9
        ):
            continue
        if (
            taken is not None
            and len(taken)
            and np.any(np.linalg.norm(np.asarray(taken) - centre, axis=1) < 2 * candidate_radius)
        ):
            continue
        pts = np.vstack([others, model.nodes[node] - c])
        nrm = np.vstack([other_n, -model.normals[node]])
        res = lp.solve(pts, nrm, fmax, active, wrench, model.contact_friction, model.mean_radius)
        if res.feasible:
            values[k] = res.total
    if np.isfinite(values).any():
        return int(cand[int(np.argmin(values))]), values
    push = -model.normals[cand] @ np.asarray(wrench, float)[:2]
    return int(cand[int(np.argmax(push))]), values


# --------------------------------------------------------------------------- the rollout


@dataclass(frozen=True)
class _Transit:
    path: int  # index into Rollout._paths
    done: int  # intervals travelled
    target: int  # node


class _Sim:
    """The model's state at an interval boundary: centroid (x, y) world and unwrapped θ, the
    contact node per robot (−1: none), world robot centres, travelling relocators, the pose
    arc length s of the centroid's match on the route and its distance dev from it."""

    __slots__ = ("pose", "nodes", "pos", "transit", "s", "dev", "key")

    def __init__(self, pose, nodes, pos, transit, s, dev):
        self.pose: tuple[float, float, float] = pose
        self.nodes: tuple[int, ...] = nodes
        self.pos: FloatArray = pos
        self.transit: tuple[_Transit | None, ...] = transit
        self.s: float = s
        self.dev: float = dev
        self.key = (pose, nodes, transit, pos.tobytes())

    def same(self, other: _Sim) -> bool:
        return self.key == other.key


@dataclass(frozen=True, eq=False)
class _Terms:
    collision: bool
    infeasible: bool
    force: float  # Σ|f| (N)
    deviation: float  # m
    forces: FloatArray  # (k,) normal force per robot (N)


@dataclass(frozen=True, eq=False)
class Trace:
    """A rolled-out action matrix: states at the n + 1 interval boundaries, per interval the
    effective actions, energy terms, twist (world, of the centroid), LP answer."""

    matrix: IntArray
    sims: tuple[_Sim, ...]
    effective: tuple[tuple[int, ...], ...]
    terms: tuple[_Terms, ...]
    twists: tuple[FloatArray, ...]
    lps: tuple[LPResult, ...]


def _rot(th: float) -> FloatArray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


class Rollout:
    """Rolls action matrices out from one :class:`TransportState` (see the module docstring).

    ``lp``: a :class:`ContactForceLP` for at least as many contacts as robots (one is made if
    None); ``scans``: a dict kept across plans that caches relocation scans by (robot, the
    others' contact nodes, the needed wrench's direction to 0.02). Steps are memoised by
    (state, action row, twist override) within the object.
    """

    def __init__(
        self,
        state: TransportState,
        params: TransportParams,
        lp: ContactForceLP | None = None,
        scans: dict | None = None,
    ):
        m: ObjectModel = state.model
        self.state, self.params, self.model = state, params, m
        robots = state.robots
        self.k = len(robots)
        self.radii = np.array([r.radius for r in robots], float)
        self.fmax = np.array([r.max_force for r in robots], float)
        self.vmax = np.array([r.max_speed for r in robots], float)
        friction = m.contact_friction > 0
        if lp is None or lp.n_max < max(self.k, 1) or lp.friction != friction:
            lp = ContactForceLP(max(self.k, 1), friction=friction)
        self.lp = lp
        self._rel = m.nodes - m.centroid  # node positions about the centroid
        self._centres = self._rel[None] + self.radii[:, None, None] * m.normals[None]
        self._rel_list = self._rel.tolist()
        self._centres_list = self._centres.tolist()
        self._pi, self._pj = np.triu_indices(self.k, 1)
        self._bounds = None
        if state.bounds is not None:
            b = np.asarray(state.bounds, float)
            self._bounds = (b[0] + self.radii[:, None], b[1] - self.radii[:, None])
        self._vmax_list = self.vmax.tolist()
        pose = np.asarray(state.pose, float)
        cw = geometry.transform(m.centroid[None], pose)[0]
        self.route = RoutePath(state.route.waypoints, state.route.subgoal, m)
        th = self.route.unwrap_heading(float(pose[2]), cw)
        self.route.focus([cw[0], cw[1], m.mean_radius * th])
        nodes = tuple(
            -1 if r.contact is None else m.snap(r.contact[0], r.contact[1]) for r in robots
        )
        pos = np.array([np.asarray(r.position, float) for r in robots]).reshape(self.k, 2)
        start_pose = (float(cw[0]), float(cw[1]), th)
        self._pair_gap2 = self._pair_gaps(nodes, pos, cw, float(pose[2]))
        s0, dev0, _ = self.route.locate(self._q(start_pose))
        self.start = _Sim(start_pose, nodes, pos, (None,) * self.k, s0, dev0)
        self.s0 = s0
        # Vass: the intervals divide the time to the subgoal, t_s / n (never below `interval`)
        t_s = max(self.route.s_subgoal - s0, 0.0) / params.speed
        self.dt = max(params.interval, t_s / params.intervals)
        self._slide_steps = max(1, int(round(params.slide_speed * self.dt / m.node_spacing)))
        cw, ccw = np.arange(len(m.nodes)), np.arange(len(m.nodes))
        for _ in range(self._slide_steps):  # where one interval of sliding ends, per node
            cw, ccw = m.next_cw[cw], m.next_ccw[ccw]
        self._slid_cw, self._slid_ccw = cw.tolist(), ccw.tolist()
        self.previous = tuple(-1 if r.action is None else action_code(r.action) for r in robots)
        self._lp_cache: dict[tuple, LPResult] = {}
        self._memo: dict[tuple, tuple] = {}
        self._paths: list[list[list[float]]] = []
        self._path_index: dict[tuple, int] = {}
        # relocation targets: the committed ones (robots already on their way) first
        self.targets: dict[int, int] = {
            i: m.snap(r.target[0], r.target[1]) for i, r in enumerate(robots) if r.target
        }
        self._scans = {} if scans is None else scans
        self.lp_calls = 0
        self.steps = 0

    # ------------------------------------------------------------------ helpers

    def _pair_gaps(self, nodes, pos: FloatArray, cw: FloatArray, th: float) -> FloatArray:
        """The squared centre distance under which a pair of robots collides: their radii
        less the contact tolerance; under the error model (``pose_error``) twice the motion
        error more, except for a pair nearer than that at the plan's start (where the model
        puts them: robots in contact at their nodes), which may stay as near, not close in."""
        p = self.params
        gap = self.radii[self._pi] + self.radii[self._pj] - p.contact_tolerance
        if p.pose_error > 0 and self.k > 1:
            at = pos.copy()
            rot = geometry.rot(th)
            for i, n in enumerate(nodes):
                if n >= 0:
                    at[i] = cw + rot @ self._centres[i, n]
            start = np.linalg.norm(at[self._pi] - at[self._pj], axis=1)
            gap = np.maximum(gap, np.minimum(gap + 2.0 * p.pose_error, start - 1e-3))
        return np.maximum(gap, 0.0) ** 2

    def _q(self, pose: tuple[float, float, float]) -> FloatArray:
        return np.array([pose[0], pose[1], self.model.mean_radius * pose[2]])

    def object_pose(self, sim: _Sim) -> FloatArray:
        """World pose of the object frame for a state."""
        x, y, th = sim.pose
        origin = np.array([x, y]) - _rot(th) @ self.model.centroid
        return np.array([origin[0], origin[1], float(geometry.wrap_angle(th))])

    def carrot_twist(self, sim: _Sim) -> FloatArray:
        """Commanded world twist of the centroid (vx, vy m/s, ω rad/s) toward the carrot, before
        the robots' speed limits."""
        p, rbar = self.params, self.model.mean_radius
        ahead = max(p.lookahead, p.speed * self.dt)  # never closer than one interval's travel
        tx, ty, tz = self.route.at(min(sim.s + ahead, self.route.s_subgoal)).tolist()
        ex, ey, ez = tx - sim.pose[0], ty - sim.pose[1], tz - rbar * sim.pose[2]
        dist = math.sqrt(ex * ex + ey * ey + ez * ez)
        if dist < 1e-6:
            return np.zeros(3)
        k = min(p.speed, dist / self.dt) / dist
        return np.array([ex * k, ey * k, ez * k / rbar])

    def _speed_scale(self, th: float, eff, nodes, att, twist: FloatArray) -> float:
        """Largest factor ≤ 1 keeping every attached robot within its max_speed."""
        v0, v1, w = float(twist[0]), float(twist[1]), float(twist[2])
        if v0 == 0.0 and v1 == 0.0 and w == 0.0:
            return 1.0
        c, s = math.cos(th), math.sin(th)
        scale = 1.0
        slide = self.params.slide_speed
        for i in range(self.k):
            if not att[i]:
                continue
            x, y = self._rel_list[nodes[i]]
            rx, ry = c * x - s * y, s * x + c * y
            vp = math.hypot(v0 - w * ry, v1 + w * rx)
            room = self._vmax_list[i] - (slide if eff[i] in (SLIDE_LEFT, SLIDE_RIGHT) else 0.0)
            if vp > 1e-12:
                scale = min(scale, max(room, 0.0) / vp)
        return scale

    def forces(self, th: float, push: IntArray, nodes, twist_world: FloatArray) -> LPResult:
        """The LP for the pushers (robot indices) at their nodes, for a world twist."""
        m = self.model
        c, s = math.cos(th), math.sin(th)
        twist_obj = np.array(
            [
                c * twist_world[0] + s * twist_world[1],
                -s * twist_world[0] + c * twist_world[1],
                twist_world[2],
            ]
        )
        nd = nodes[push]
        key = (twist_obj.tobytes(), push.tobytes(), nd.tobytes())
        hit = self._lp_cache.get(key)
        if hit is None:
            w = required_wrench(twist_obj, m.mass, m.floor_friction, m.mean_radius)
            hit = None
            for wrench in robust_wrenches(w, self.params.com_error):
                res = self.lp.solve(
                    self._rel[nd],
                    -m.normals[nd],
                    self.fmax[push],
                    np.ones(len(push), bool),
                    wrench,
                    m.contact_friction,
                    m.mean_radius,
                )
                self.lp_calls += 1
                if hit is None or not res.feasible or (hit.feasible and res.total > hit.total):
                    hit = res  # the worst of them: infeasible if any is
                if not res.feasible:
                    break
            self._lp_cache[key] = hit
        return hit

    def relocation_target(self, i: int) -> int:
        """The scan's node for robot i, from the plan's starting configuration (cached)."""
        if i in self.targets:
            return self.targets[i]
        m, st = self.model, self.start
        others = np.array([j for j in range(self.k) if j != i and st.nodes[j] >= 0], np.int64)
        twist = self.carrot_twist(st)
        v = _rot(-st.pose[2]) @ twist[:2]
        w = required_wrench([v[0], v[1], twist[2]], m.mass, m.floor_friction, m.mean_radius)
        if not np.any(w):
            w = np.array([1.0, 0.0, 0.0])  # nothing to push: the node pushing along +x
        nodes = np.array([st.nodes[j] for j in others], np.int64)
        unit = w / max(float(np.linalg.norm(w / [1.0, 1.0, m.mean_radius])), 1e-12)
        # where the other relocating robots are going is taken too
        taken = np.array(
            [m.centre(n, self.radii[j]) for j, n in self.targets.items() if j != i]
        ).reshape(-1, 2)
        key = (i, nodes.tobytes(), np.round(unit / 0.02).astype(int).tobytes(), taken.tobytes())
        if key not in self._scans:
            self._scans[key] = relocation_scan(
                m,
                nodes,
                self.fmax[others],
                self.radii[others],
                self.radii[i],
                self.fmax[i],
                w,
                self.lp,
                taken=taken,
            )[0]
        self.targets[i] = self._scans[key]
        return self.targets[i]

    def _path(self, i: int, sim: _Sim, target: int) -> int:
        """Index of robot i's relocation path to ``target`` from where it is: the object-frame
        points (about the centroid) it reaches at the end of each interval of travel."""
        m = self.model
        if sim.nodes[i] >= 0:
            start = m.centre(sim.nodes[i], self.radii[i])
            key = (i, "node", sim.nodes[i], target)
        else:
            x, y, th = sim.pose
            start = _rot(-th) @ (sim.pos[i] - np.array([x, y])) + m.centroid
            key = (i, "free", start.tobytes(), target)
        if key not in self._path_index:
            path = relocation_path(m, start, m.centre(target, self.radii[i]))
            cum = _cumulative(path)
            step = self.vmax[i] * self.dt
            count = max(1, int(math.ceil(cum[-1] / step - 1e-9)))
            stops = [
                (_along(path, cum, step * (c + 1)) - m.centroid).tolist() for c in range(count)
            ]
            self._path_index[key] = len(self._paths)
            self._paths.append(stops)
        return self._path_index[key]

    # ------------------------------------------------------------------ one interval

    def effective(self, sim: _Sim, row: IntArray) -> tuple[int, ...]:
        """The actions the model executes: travelling relocators keep travelling, robots
        without contact relocate or idle."""
        out = []
        for i in range(self.k):
            a = int(row[i])
            if sim.transit[i] is not None:
                a = RELOCATE
            elif sim.nodes[i] < 0 and a != RELOCATE:
                a = IDLE
            out.append(a)
        return tuple(out)

    def step(self, sim: _Sim, row: IntArray, twist_override: FloatArray | None = None):
        """One interval: (next state, effective actions, terms, world twist, LP answer).
        ``twist_override``: the world twist to move with instead of the carrot's (then scaled
        to the robots' limits like the carrot's)."""
        row = np.asarray(row, np.int64)
        ov = None if twist_override is None else np.asarray(twist_override, float)
        key = (sim.key, row.tobytes(), None if ov is None else ov.tobytes())
        hit = self._memo.get(key)
        if hit is None:
            hit = self._step(sim, row, ov)
            self._memo[key] = hit
        return hit

    def _step(self, sim: _Sim, row: IntArray, override: FloatArray | None):
        self.steps += 1
        eff = list(self.effective(sim, row))
        nodes = list(sim.nodes)
        transit = list(sim.transit)
        self._start_relocations(sim, eff, nodes, transit)
        att = [nodes[i] >= 0 and eff[i] in ATTACHED for i in range(self.k)]
        want = self.carrot_twist(sim) if override is None else override
        want = want * self._speed_scale(sim.pose[2], eff, nodes, att, want)
        ok, held = self.model.pushable, self.start.nodes
        # a push within the error model's margin of a vertex counts for nothing (a robot sent
        # there may reach the corner, or pass it): the object moves only if the others move it.
        # The contact a robot holds at the plan's start counts: the margin is for contacts the
        # plan moves a robot to (the held one is measured, its error already in it)
        push = [
            i
            for i in range(self.k)
            if eff[i] == PUSH and nodes[i] >= 0 and (ok[nodes[i]] or nodes[i] == held[i])
        ]
        push = np.array(push, np.int64)
        lp = self.forces(sim.pose[2], push, np.array(nodes, np.int64), want)
        moved = want if lp.feasible else np.zeros(3)
        dt = self.dt
        x, y, th = sim.pose
        pose = (x + float(moved[0]) * dt, y + float(moved[1]) * dt, th + float(moved[2]) * dt)
        still = pose == sim.pose
        pos, hit = self._move_robots(sim, pose, eff, nodes, att, transit, not still)
        if still:
            s_new, dev = sim.s, sim.dev
        else:
            s_new, dev, _ = self.route.locate(self._q(pose))
        new = _Sim(pose, tuple(nodes), pos, tuple(transit), s_new, dev)
        per_robot = np.zeros(self.k)
        force = 0.0
        if lp.feasible and len(push):
            force = float(np.sum(np.hypot(lp.normal, lp.tangential)))
            per_robot[push] = lp.normal
        terms = _Terms(
            collision=hit or self._collides(new),
            infeasible=not lp.feasible,
            force=force,
            deviation=dev,
            forces=per_robot,
        )
        return new, tuple(eff), terms, moved, lp

    def _start_relocations(self, sim: _Sim, eff: list, nodes: list, transit: list) -> None:
        """Robots told to relocate leave their contact for the scan's node (in place)."""
        for i in range(self.k):
            if eff[i] != RELOCATE or transit[i] is not None:
                continue
            target = self.relocation_target(i)
            if target == nodes[i]:  # already where the scan wants it: it pushes there
                eff[i] = PUSH
                continue
            transit[i] = _Transit(self._path(i, sim, target), 0, target)
            nodes[i] = -1

    def _move_robots(self, sim: _Sim, pose, eff, nodes, att, transit, moved: bool):
        """Moves robots (nodes and transit updated in place); returns (positions, hit)."""
        cx, cy, th = pose
        c, s = math.cos(th), math.sin(th)
        pos = sim.pos.tolist()
        free = []
        for i in range(self.k):
            tr = transit[i]
            if tr is not None:
                stops = self._paths[tr.path]
                if tr.done + 1 >= len(stops):
                    nodes[i], transit[i] = tr.target, None
                else:
                    transit[i] = _Transit(tr.path, tr.done + 1, tr.target)
                x, y = stops[min(tr.done, len(stops) - 1)]
            elif att[i]:
                nodes[i] = self._slide(nodes[i], eff[i])
                x, y = self._centres_list[i][nodes[i]]
            else:
                free.append(i)
                continue
            pos[i] = [cx + c * x - s * y, cy + s * x + c * y]
        out = np.array(pos)
        if not (moved and free):
            return out, False
        return out, self._idle_contacts(out, free, nodes, (cx, cy, c, s))

    def _slide(self, node: int, a: int) -> int:
        if a == SLIDE_LEFT:  # the robot's left as it faces the object: clockwise
            return self._slid_cw[node]
        if a == SLIDE_RIGHT:
            return self._slid_ccw[node]
        return node

    def _idle_contacts(self, pos: FloatArray, free: list, nodes: list, frame) -> bool:
        """Robots standing still next to the moved object: those it left lose contact; returns
        whether it moved into one."""
        cx, cy, c, s = frame
        m = self.model
        idle = np.array(free)
        rel = pos[idle] - np.array([cx, cy])
        local = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
        sd = geometry.polygon_signed_distance(local + m.centroid, m.polygon) - self.radii[idle]
        tol = self.params.contact_tolerance
        for i in idle[sd > tol].tolist():
            nodes[i] = -1
        return bool(np.any(sd < -tol))

    def _collides(self, sim: _Sim) -> bool:
        pos = sim.pos
        if self.k > 1:
            d = pos[self._pi] - pos[self._pj]
            if bool(((d * d).sum(1) < self._pair_gap2).any()):
                return True
        if self._bounds is not None:
            lo, hi = self._bounds
            if bool((pos < lo).any()) or bool((pos > hi).any()):
                return True
        return bool(self.state.obstacles) and self._hits_obstacles(sim)

    def _hits_obstacles(self, sim: _Sim) -> bool:
        poly = geometry.transform(self.model.polygon, self.object_pose(sim))
        for obs in self.state.obstacles:
            if np.any(geometry.discs_hit_polygon(sim.pos, self.radii, obs)):
                return True
            if geometry.points_in_polygon(poly, obs).any():
                return True
            if geometry.points_in_polygon(obs, poly).any():
                return True
        return False

    # ------------------------------------------------------------------ whole matrices

    def run(self, matrix: IntArray, overrides: list[FloatArray | None] | None = None) -> Trace:
        """Roll a whole (intervals, robots) matrix out from the start state."""
        return self.rerun(None, np.asarray(matrix, np.int64), 0, overrides)

    def rerun(
        self,
        trace: Trace | None,
        matrix: IntArray,
        j: int,
        overrides: list[FloatArray | None] | None = None,
    ) -> Trace:
        """Roll ``matrix`` out again from interval j of ``trace`` (which rolled out a matrix
        equal to this one before interval j); stops early once a state repeats."""
        n = len(matrix)
        if np.ndim(matrix) != 2 or np.shape(matrix)[1] != self.k:
            raise ValueError(
                f"action matrix: expected (intervals, {self.k}), got {np.shape(matrix)}"
            )
        if trace is None:
            sims, eff, terms, tw, lps = [self.start], [], [], [], []
            j = 0
        else:
            sims = list(trace.sims[: j + 1])
            eff, terms = list(trace.effective[:j]), list(trace.terms[:j])
            tw, lps = list(trace.twists[:j]), list(trace.lps[:j])
        for jj in range(j, n):
            if trace is not None and jj > j and sims[jj].same(trace.sims[jj]):
                sims += trace.sims[jj + 1 :]
                eff += trace.effective[jj:]
                terms += trace.terms[jj:]
                tw += trace.twists[jj:]
                lps += trace.lps[jj:]
                break
            ov = None if overrides is None else overrides[jj]
            s, e, t, w, lp = self.step(sims[jj], matrix[jj], ov)
            sims.append(s)
            eff.append(e)
            terms.append(t)
            tw.append(w)
            lps.append(lp)
        return Trace(matrix, tuple(sims), tuple(eff), tuple(terms), tuple(tw), tuple(lps))

    def energy(self, trace: Trace) -> Energy:
        p = self.params
        collisions = sum(t.collision for t in trace.terms)
        infeasible = sum(t.infeasible for t in trace.terms)
        force = float(sum(t.force for t in trace.terms))
        deviation = float(sum(t.deviation for t in trace.terms))
        changes = count_changes(np.array(trace.effective, np.int64), self.previous)
        progress = trace.sims[-1].s - self.s0
        total = (
            p.k_collision * collisions
            + p.k_equilibrium * infeasible
            + p.k_force * force
            + p.k_change * changes
            + p.k_deviation * deviation
            - p.k_progress * progress
        )
        return Energy(total, collisions, infeasible, force, changes, deviation, progress)


def count_changes(effective: IntArray, previous: tuple[int, ...]) -> int:
    """Action changes per robot between consecutive intervals, the first interval against the
    robot's previous action (−1: none, not counted)."""
    eff = np.asarray(effective, np.int64).reshape(-1, len(previous))
    prev = np.asarray(previous, np.int64)
    first = int(np.sum((prev >= 0) & (eff[0] != prev))) if len(eff) else 0
    return first + int(np.sum(eff[1:] != eff[:-1]))


def hold_matrix(roll: Rollout, intervals: int) -> IntArray:
    """Each robot repeats its last action; a robot without one pushes if its push has a
    component along the force the object needs now (else it follows), or idles without
    contact."""
    m, st = roll.model, roll.start
    twist = roll.carrot_twist(st)
    need = _rot(-st.pose[2]) @ twist[:2]
    row = []
    for i, r in enumerate(roll.state.robots):
        if r.action is not None:
            row.append(action_code(r.action))
        elif st.nodes[i] < 0:
            row.append(IDLE)
        else:
            row.append(PUSH if float(-m.normals[st.nodes[i]] @ need) > 1e-9 else FOLLOW)
    return np.tile(np.array(row, np.int64), (intervals, 1))


def lp_matrix(roll: Rollout, intervals: int) -> IntArray:
    """The least-force pushing set as the start: a robot in the middle of a relocation or a
    slide keeps at it; the robots in contact push if the contact-force LP with all of them as
    candidates gives them a force for the twist the route asks for now, else follow (a start
    that already moves the object, where every single change from "everyone follows" is
    uphill); without an LP answer, :func:`hold_matrix`."""
    st = roll.start
    twist = roll.carrot_twist(st)
    contact = np.array([i for i in range(roll.k) if st.nodes[i] >= 0], np.int64)
    force = np.zeros(roll.k)
    if len(contact) and np.any(twist):
        res = roll.forces(st.pose[2], contact, np.asarray(st.nodes, np.int64), twist)
        if res.status == "optimal":
            force[contact] = res.normal
    if not np.any(force > 1e-6):
        return hold_matrix(roll, intervals)
    row = []
    for i, r in enumerate(roll.state.robots):
        last = None if r.action is None else action_code(r.action)
        if last in (RELOCATE, SLIDE_LEFT, SLIDE_RIGHT):
            row.append(last)
        elif st.nodes[i] < 0:
            row.append(IDLE)
        else:
            row.append(PUSH if force[i] > 1e-6 else FOLLOW)
    return np.tile(np.array(row, np.int64), (intervals, 1))
