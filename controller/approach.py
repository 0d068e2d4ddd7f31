"""Projective path planning to moving capture points (Sharma et al. 2007, §3): pure, per tick.

Every tick each robot has a goal (its capture point's image on the convex envelope, or the point
itself when closing in). It turns its heading of motion toward the goal by at most
``max_turn_deg`` (§3.2), projects its disc ahead by ``projection``·r along that direction (§3.3)
and, if the projected disc meets the object or a static obstacle (the paper's pseudo-agents),
applies Table I:

- one edge hit: move along that edge, in the direction with positive dot product with the
  heading;
- two edges hit (a corner): move along the bisector of the two outward normals, away;
- head-on (the projected centre inside the polygon): escape along the nearest edge's outward
  normal at full speed.

Robot–robot (§3.5): if the projected disc meets another robot's disc, rotate the projection by
±α (the first sign from the seeded generator, then the other), widen α by ``alpha_growth`` and
repeat until clear or α passes ``alpha_max_deg``; then the robot stops this tick. The paper
moves a robot 2d–3d at once; a real robot cannot jump, so the result is a velocity (direction ×
speed) for the safety filter and the kinematics. No I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from controller import geometry

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ApproachParams:
    max_turn: float = np.radians(15.0)  # rad per tick
    projection: float = 2.5  # × r
    alpha: float = np.radians(15.0)
    alpha_growth: float = 1.25
    alpha_max: float = np.radians(180.0)
    envelope_margin: float = 0.25  # m
    contact_gap: float = 0.01  # m
    gain: float = 2.0  # 1/s
    clearance: float = 0.02  # m kept from polygons by the projection test
    station_gap: float = 0.1  # m between two stations' discs, and from station to contact goal

    @classmethod
    def from_config(cls, a) -> ApproachParams:
        return cls(
            max_turn=np.radians(a.max_turn_deg),
            projection=a.projection,
            alpha=np.radians(a.alpha_deg),
            alpha_growth=a.alpha_growth,
            alpha_max=np.radians(a.alpha_max_deg),
            envelope_margin=a.envelope_margin,
            contact_gap=a.contact_gap,
            gain=a.tracking_gain,
        )


# --------------------------------------------------------------------------- goals


def envelope(polygon_world: FloatArray, margin: float) -> FloatArray:
    """The convex envelope: the hull of the object's outline (the margin is applied to goals)."""
    return geometry.convex_hull(polygon_world)


def ray_exit(points: FloatArray, dirs: FloatArray, hull: FloatArray) -> FloatArray:
    """Distance along each ray (point, unit direction) to where it leaves a convex polygon
    (0 for a ray starting outside or on the boundary facing out)."""
    a = hull
    b = np.roll(hull, -1, axis=0)
    e = b - a  # (E, 2)
    # solve p + t d = a + s e for each ray and edge
    den = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]
    ap = a[None] - points[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[..., 0] * e[None, :, 1] - ap[..., 1] * e[None, :, 0]) / den
        s = (ap[..., 0] * dirs[:, None, 1] - ap[..., 1] * dirs[:, None, 0]) / den
    ok = (np.abs(den) > 1e-12) & (s >= -1e-9) & (s <= 1 + 1e-9) & (t >= -1e-9)
    t = np.where(ok, t, 0.0)
    return np.max(t, axis=1)


def capture_goals(
    points: FloatArray,
    normals: FloatArray,
    radii: FloatArray,
    object_pose: FloatArray,
    polygon: FloatArray,
    params: ApproachParams,
) -> tuple[FloatArray, FloatArray]:
    """World-frame goals for robots at capture points (object-frame points and outward normals):
    the envelope images (outside the convex hull by ``envelope_margin`` + r along the normal)
    and the contact goals (r + ``contact_gap`` out along the normal)."""
    p_w = geometry.transform(points, object_pose)
    n_w = normals @ geometry.rot(float(object_pose[2])).T
    hull = envelope(geometry.transform(polygon, object_pose), params.envelope_margin)
    out = ray_exit(p_w, n_w, hull) + params.envelope_margin + radii
    out = separate_stations(p_w, n_w, out, radii, params)
    env = p_w + n_w * out[:, None]
    contact = p_w + n_w * (radii + params.contact_gap)[:, None]
    return env, contact


def separate_stations(
    p: FloatArray, n: FloatArray, out: FloatArray, radii: FloatArray, params: ApproachParams
) -> FloatArray:
    """Distances along the normals for the stations, pulled in where two stations would be
    closer than their discs plus ``station_gap`` (points in a notch: their rays converge
    outside it). Never closer to the object than the contact goal plus ``station_gap``."""
    out = out.copy()
    floor = radii + params.contact_gap + params.station_gap
    m = len(p)
    for _ in range(50):
        st = p + n * out[:, None]
        d = np.linalg.norm(st[:, None] - st[None], axis=-1)
        need = radii[:, None] + radii[None] + params.station_gap
        bad = (d < need) & ~np.eye(m, dtype=bool)
        if not bad.any():
            break
        shrink = bad.any(axis=1) & (out > floor)
        if not shrink.any():
            break
        out[shrink] = np.maximum(floor[shrink], out[shrink] - 0.02)
    return out


# --------------------------------------------------------------------------- Table I


def table_one(
    centre: FloatArray, radius: float, direction: FloatArray, polygon: FloatArray, clearance: float
) -> tuple[str, FloatArray]:
    """Table I for one projected disc against one polygon: the rule that fired ("free", "edge",
    "corner", "head_on") and the new unit direction."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    d, t = geometry.point_segment_distance(centre[None], a, b)
    d = d[0]
    if geometry.points_in_polygon(centre[None], polygon)[0]:
        k = int(np.argmin(d))
        n = geometry.outward_normals(polygon)[k]
        return "head_on", n
    hit = np.flatnonzero(d < radius + clearance)
    if len(hit) == 0:
        return "free", direction
    normals = geometry.outward_normals(polygon)
    if len(hit) == 1:
        e = b[hit[0]] - a[hit[0]]
        e = e / np.linalg.norm(e)
        return "edge", e if e @ direction >= 0 else -e
    # a corner: the two nearest edges hit
    k1, k2 = hit[np.argsort(d[hit])[:2]]
    bis = normals[k1] + normals[k2]
    nb = np.linalg.norm(bis)
    if nb < 1e-9:
        bis = normals[k1]
        nb = 1.0
    return "corner", bis / nb


def turn_toward(current: FloatArray, desired: FloatArray, max_turn: float) -> FloatArray:
    """Headings (rad) turned from ``current`` toward ``desired`` by at most ``max_turn``."""
    err = geometry.wrap_angle(desired - current)
    return current + np.clip(err, -max_turn, max_turn)


def _unit(a: float) -> FloatArray:
    return np.array([np.cos(a), np.sin(a)])


@dataclass
class StepResult:
    velocity: FloatArray  # (N, 2) world velocity
    heading: FloatArray  # (N,) heading of motion after the turn limit
    rules: list[str]  # the rule that fired per robot


def plan_step(
    positions: FloatArray,
    radii: FloatArray,
    goals: FloatArray,
    goal_velocity: FloatArray,
    speed: FloatArray,
    motion_heading: FloatArray,
    obstacles: list[FloatArray],
    active: NDArray[np.bool_],
    params: ApproachParams,
    rng: np.random.Generator,
    avoid_object: NDArray[np.bool_] | None = None,
    object_polygon: FloatArray | None = None,
) -> StepResult:
    """One projective step for every active robot: world velocities toward the goals.

    ``obstacles`` are polygons (static, world frame); ``object_polygon`` (the object at its
    predicted pose) is avoided by the robots flagged in ``avoid_object``. ``goal_velocity`` is
    fed forward (the goal moves with the object); ``motion_heading`` is each robot's previous
    heading of motion (the turn limit's reference), updated in the result.
    """
    n = len(positions)
    vel = np.zeros((n, 2))
    heading = motion_heading.copy()
    rules = ["idle"] * n
    avoid_object = np.zeros(n, bool) if avoid_object is None else avoid_object
    for i in range(n):
        if not active[i]:
            continue
        err = goals[i] - positions[i]
        dist = float(np.linalg.norm(err))
        want = float(np.arctan2(err[1], err[0])) if dist > 1e-9 else heading[i]
        h = float(turn_toward(np.array(heading[i]), np.array(want), params.max_turn))
        direction = _unit(h)
        reach = min(params.projection * radii[i], dist)
        polys = list(obstacles)
        if avoid_object[i] and object_polygon is not None:
            polys.append(object_polygon)
        rule = "free"
        v_scale = min(float(speed[i]), params.gain * dist)
        for poly in polys:
            ahead = positions[i] + reach * direction
            r, nd = table_one(ahead, radii[i], direction, poly, params.clearance)
            if r != "free":
                rule, direction = r, nd
                if r == "head_on":
                    v_scale = float(speed[i])
                break
        # robot–robot: rotate the projection by ±alpha until clear
        others = np.flatnonzero(np.arange(n) != i)
        if len(others) and rule != "head_on":
            direction, ok = _clear_of_robots(
                positions[i], radii[i], reach, direction, positions[others], radii[others],
                params, rng,
            )  # fmt: skip
            if not ok:
                rules[i] = "blocked"
                continue
        if rule == "free" and dist > 1e-9:
            # feed the goal's motion forward; the turn limit bounds the change of direction
            v = direction * v_scale + goal_velocity[i]
        else:
            v = direction * max(v_scale, 0.3 * float(speed[i]))
        sp = float(np.linalg.norm(v))
        if sp > speed[i]:
            v *= speed[i] / sp
        vel[i] = v
        if sp > 1e-9:
            heading[i] = float(np.arctan2(v[1], v[0]))
        rules[i] = rule
    return StepResult(vel, heading, rules)


def _clear_of_robots(
    p: FloatArray,
    r: float,
    reach: float,
    direction: FloatArray,
    others: FloatArray,
    other_r: FloatArray,
    params: ApproachParams,
    rng: np.random.Generator,
) -> tuple[FloatArray, bool]:
    """§3.5: the projection rotated by ±α, α widened by the growth factor, until clear."""

    def clear(d: FloatArray) -> bool:
        ahead = p + reach * d
        gap = np.linalg.norm(others - ahead, axis=1) - other_r - r
        # only robots in front matter: ignore those we are already moving away from
        front = (others - p) @ d > 0
        return not np.any((gap < params.clearance) & front)

    if clear(direction):
        return direction, True
    base = float(np.arctan2(direction[1], direction[0]))
    alpha = params.alpha
    first = 1.0 if rng.random() < 0.5 else -1.0
    while alpha <= params.alpha_max:
        for sgn in (first, -first):
            d = _unit(base + sgn * alpha)
            if clear(d):
                return d, True
        alpha *= params.alpha_growth
    return direction, False
