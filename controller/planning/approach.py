"""Projective path planning (Sharma, Saxena, Dutta 2007, §3), per tick, all robots at once.

Pure: arrays in, arrays out. Units: metres, seconds, radians. The paper moves a robot by a
jump; here each rule yields a world-frame direction, turned into a velocity by the mission.

Table I (the robot's disc projected ahead by ``projection``·r along its heading):
- no hit: keep the heading;
- one edge: align with that edge (the edge direction with positive dot product with the heading);
- two edges (a corner): along the angular bisector of the two edge normals, away from the polygon;
- head-on (the robot's centre inside the polygon's next position): escape along the outward
  normal of the nearest edge at full speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller import geometry
from controller.config import ApproachSection, configured, from_section

NO_HIT, EDGE, CORNER, HEAD_ON = "none", "edge", "corner", "head_on"


def envelope(poly_world: np.ndarray, margin: float, samples: int = 16) -> np.ndarray:
    """Convex hull of the polygon grown by ``margin`` (CCW; a disc sampled at the vertices,
    scaled so the hull contains the true Minkowski sum)."""
    ang = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    grow = margin / np.cos(np.pi / samples)
    ring = grow * np.stack([np.cos(ang), np.sin(ang)], 1)
    pts = (poly_world[:, None, :] + ring[None]).reshape(-1, 2)
    return geometry.convex_hull(pts)


def ray_to_convex(origins: np.ndarray, dirs: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """Where rays from points inside (or on) a convex CCW hull leave it: (M, 2)."""
    a = hull
    b = np.roll(hull, -1, axis=0)
    e = b - a
    nrm = np.stack([e[:, 1], -e[:, 0]], 1)  # outward for CCW
    num = np.sum((a[None] - origins[:, None]) * nrm[None], axis=-1)  # (M, E)
    den = dirs @ nrm.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den > 1e-12, num / den, np.inf)
    t = np.where(t < 0, np.inf, t)
    tt = t.min(axis=1)
    tt = np.where(np.isfinite(tt), tt, 0.0)
    return origins + tt[:, None] * dirs


def classify(
    center: np.ndarray, heading: np.ndarray, radius: float, projection: float, poly: np.ndarray
) -> tuple[str, np.ndarray]:
    """The Table I case for one robot against one polygon, and the resulting unit direction.

    ``heading`` is a unit world direction; the disc is projected to centre + projection·r·heading.
    """
    poly = geometry.ensure_ccw(poly)
    a = poly
    b = np.roll(poly, -1, axis=0)
    e = b - a
    el = np.maximum(np.linalg.norm(e, axis=1), 1e-12)
    nrm = np.stack([e[:, 1], -e[:, 0]], 1) / el[:, None]
    if geometry.points_in_polygon(center[None], poly)[0]:
        d, _ = geometry.point_segment_distance(center[None], a, b)
        k = int(np.argmin(d[0]))
        return HEAD_ON, nrm[k]
    ahead = center + projection * radius * heading
    d, _ = geometry.point_segment_distance(ahead[None], a, b)
    inside = geometry.points_in_polygon(ahead[None], poly)[0]
    hit = np.flatnonzero(d[0] < radius)
    if inside and len(hit) == 0:
        hit = np.array([int(np.argmin(d[0]))])
    if len(hit) == 0:
        return NO_HIT, heading
    if len(hit) == 1:
        t = e[hit[0]] / el[hit[0]]
        return EDGE, t if np.dot(t, heading) >= 0 else -t
    # corner: two (or more) edges; bisector of the closest two edges' outward normals
    order = hit[np.argsort(d[0][hit])][:2]
    bis = nrm[order[0]] + nrm[order[1]]
    s = np.linalg.norm(bis)
    if s < 1e-9:
        bis = nrm[order[0]]
        s = 1.0
    return CORNER, bis / s


def turn_limited(current: np.ndarray, desired: np.ndarray, max_turn: float) -> np.ndarray:
    """Unit directions (N, 2): ``current`` turned toward ``desired`` by at most ``max_turn`` rad."""
    a0 = np.arctan2(current[:, 1], current[:, 0])
    a1 = np.arctan2(desired[:, 1], desired[:, 0])
    da = np.clip(geometry.wrap_angle(a1 - a0), -max_turn, max_turn)
    a = a0 + da
    return np.stack([np.cos(a), np.sin(a)], 1)


def rotate(v: np.ndarray, ang: float) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def robot_rotation(
    i: int,
    centers: np.ndarray,
    radii: np.ndarray,
    direction: np.ndarray,
    projection: float,
    alpha: float,
    growth: float,
    alpha_max: float,
    rng: np.random.Generator,
    ignore: np.ndarray | None = None,
) -> np.ndarray | None:
    """§3.5: rotate robot i's projection by ±alpha (first sign from ``rng``), widening by
    ``growth`` until the projected disc clears every other robot; None if the bound is reached."""

    def clear(dvec: np.ndarray) -> bool:
        ahead = centers[i] + projection * radii[i] * dvec
        d = np.linalg.norm(centers - ahead, axis=1)
        ok = d >= radii + radii[i]
        ok[i] = True
        if ignore is not None:
            ok |= ignore
        return bool(np.all(ok))

    if clear(direction):
        return direction
    sign = 1.0 if rng.random() < 0.5 else -1.0
    a = alpha
    while a <= alpha_max + 1e-9:
        for s in (sign, -sign):
            cand = rotate(direction, s * a)
            if clear(cand):
                return cand
        a *= growth
    return None


_APPROACH = ApproachSection()  # the config's defaults


@dataclass(frozen=True)
class PlannerParams:
    """The projective planner's parameters (Sharma Table I), each configured default the
    ``[approach]`` section's, converted to SI (rad)."""

    max_turn: float = configured(_APPROACH, "max_turn_deg", np.deg2rad)  # rad per tick
    projection: float = configured(_APPROACH, "projection")
    alpha: float = configured(_APPROACH, "alpha_deg", np.deg2rad)  # rad
    alpha_growth: float = configured(_APPROACH, "alpha_growth")
    alpha_max: float = configured(_APPROACH, "alpha_max_deg", np.deg2rad)  # rad
    gain: float = 1.5  # 1/s, proportional on the distance to the goal
    # m over which the goal's own velocity (feed-forward) fades in as the robot nears it; None:
    # always all of it (the rule before, a baseline for bench/arrest.py). A far goal is a
    # meeting point already predicted (interception): riding on the target's velocity on the
    # way there slows a robot that comes at an object head-on to the difference of the speeds
    ride_reach: float | None = 1.0

    @classmethod
    def from_config(cls, ap) -> PlannerParams:
        """From an ``ApproachSection``: ``intercept = "oncoming"`` rides on the object's
        velocity within the last metre, ``"classic"`` all the way."""
        return from_section(cls, ap, ride_reach=1.0 if ap.intercept == "oncoming" else None)


def plan_velocities(
    centers: np.ndarray,
    headings: np.ndarray,
    radii: np.ndarray,
    max_speed: np.ndarray,
    goals: np.ndarray,
    goal_velocity: np.ndarray,
    polygons: list[np.ndarray],
    avoid: np.ndarray,
    active: np.ndarray,
    params: PlannerParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """World velocities (N, 2) and new unit headings (N, 2) for every robot, and each robot's
    Table I case. ``avoid`` (N, P) says which polygons a robot must respect (the object is
    lifted for a robot closing in on its own contact point); inactive robots get zero."""
    n = len(centers)
    vel = np.zeros((n, 2))
    new_head = headings.copy()
    cases = [NO_HIT] * n
    err = goals - centers
    dist = np.linalg.norm(err, axis=1)
    want = err / np.maximum(dist, 1e-9)[:, None]
    far = dist > 1e-3
    turned = turn_limited(headings, np.where(far[:, None], want, headings), params.max_turn)
    # when the goal is close, go straight (a tight turn circle would orbit it)
    close = dist < 3 * radii * params.projection
    dirs = np.where(close[:, None], want, turned)
    speed_fb = np.minimum(params.gain * dist, max_speed)
    reach = np.minimum(params.projection, dist / radii)
    # vectorised pre-check: which robot/polygon pairs can trigger a Table I rule at all
    ahead = centers + (reach * radii)[:, None] * dirs
    near = np.zeros((n, len(polygons)), bool)
    for k, poly in enumerate(polygons):
        near[:, k] = (geometry.polygon_signed_distance(ahead, poly) < radii) | (
            geometry.polygon_signed_distance(centers, poly) < 0
        )
    near &= avoid
    for i in np.flatnonzero(active):
        dvec = dirs[i]
        case = NO_HIT
        full = False
        for k, poly in enumerate(polygons):
            if not near[i, k]:
                continue
            c, dnew = classify(centers[i], dvec, radii[i], reach[i], poly)
            if c != NO_HIT:
                case, dvec = c, dnew
                full = c == HEAD_ON
                break
        rot = robot_rotation(
            i,
            centers,
            radii,
            dvec,
            reach[i],
            params.alpha,
            params.alpha_growth,
            params.alpha_max,
            rng,
            ignore=~active,
        )
        cases[i] = case
        if rot is None and not full:
            vel[i] = 0.0
            continue
        if rot is not None:
            dvec = rot
        new_head[i] = dvec
        sp = max_speed[i] if full else speed_fb[i]
        v = sp * dvec
        if case == NO_HIT:
            v = v + _ride_share(dist[i], params.ride_reach) * goal_velocity[i]
        s = np.linalg.norm(v)
        if s > max_speed[i]:
            v *= max_speed[i] / s
        vel[i] = v
    return vel, new_head, cases


def _ride_share(dist: float, reach: float | None) -> float:
    """The share of the goal's velocity a robot ``dist`` m from it rides on: all of it at the
    goal, none from ``reach`` m on (None: all of it everywhere)."""
    if reach is None:
        return 1.0
    return float(np.clip(1.0 - dist / max(reach, 1e-9), 0.0, 1.0))


def limit_accel(v_new: np.ndarray, v_old: np.ndarray, max_accel: np.ndarray, dt: float):
    """Bound the change of world velocities (N, 2) to ``max_accel``·dt per tick."""
    dv = v_new - v_old
    s = np.linalg.norm(dv, axis=1)
    cap = max_accel * dt
    k = np.where(s > cap, cap / np.maximum(s, 1e-12), 1.0)
    return v_old + dv * k[:, None]


STATION_GAP = 0.1  # m between two stations' discs, and between a station and the contact target


def separate_stations(
    pts: np.ndarray,
    nrm: np.ndarray,
    out: np.ndarray,
    radii: np.ndarray,
    contact_gap: float,
    gap: float = STATION_GAP,
) -> np.ndarray:
    """Distances of the stations out along the normals, pulled in where two stations would be
    closer than the two discs plus ``gap`` (points in an L's or a U's notch have rays that
    converge outside it), and never closer to the object than the contact target plus ``gap``."""
    floor = radii + contact_gap + gap
    out = np.maximum(out, floor)
    off = ~np.eye(len(pts), dtype=bool)
    need = radii[:, None] + radii[None] + gap
    for _ in range(100):
        st = pts + nrm * out[:, None]
        d = np.linalg.norm(st[:, None] - st[None], axis=-1)
        shrink = ((d < need) & off).any(axis=1) & (out > floor)
        if not shrink.any():
            break
        out[shrink] = np.maximum(floor[shrink], out[shrink] - 0.02)
    return out


def static_free_distance(
    origins: np.ndarray,
    dirs: np.ndarray,
    clearance: np.ndarray,
    grown_obstacles: list[np.ndarray],
    bounds: np.ndarray | None,
) -> np.ndarray:
    """How far (m) along each unit ray a disc centre may go and stay ``clearance`` (M,) clear of
    the room's walls (``bounds`` [[x0, y0], [x1, y1]], None: no walls) and of obstacles given
    already grown by the largest clearance (convex hulls, CCW). 0 where the origin itself is
    too close (the point is out of reach); inf where nothing is in the way.

    An approach station beyond this distance could never be reached: the safety filter keeps
    the robot off the wall, and the approach would wait for it until its timeout."""
    o = np.asarray(origins, float)
    d = np.asarray(dirs, float)
    c = np.asarray(clearance, float)
    out = np.full(len(o), np.inf)
    if bounds is not None:
        lo = np.asarray(bounds, float)[0] + c[:, None]
        hi = np.asarray(bounds, float)[1] - c[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            s_lo = np.where(d < -1e-9, (o - lo) / -d, np.inf)
            s_hi = np.where(d > 1e-9, (hi - o) / d, np.inf)
        out = np.minimum(out, np.minimum(s_lo, s_hi).min(axis=1))
    for g in grown_obstacles:
        inside = geometry.points_in_polygon(o, g)
        hit = ray_first_hit(o, d, g)
        out = np.minimum(out, np.where(inside, 0.0, hit))
    return np.maximum(out, 0.0)


def ray_first_hit(origins: np.ndarray, dirs: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance along each ray to its first crossing of a polygon edge, ignoring the edge the
    ray starts on (inf when it never crosses): a ray out of a deep notch hits the object's own
    arm before it leaves the convex envelope."""
    a = poly
    e = np.roll(poly, -1, axis=0) - a
    den = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]
    ap = a[None] - origins[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[..., 0] * e[None, :, 1] - ap[..., 1] * e[None, :, 0]) / den
        u = (ap[..., 0] * dirs[:, None, 1] - ap[..., 1] * dirs[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (u >= 0) & (u <= 1) & (t > 1e-6)
    return np.where(hit, t, np.inf).min(axis=1)


def interception_times(
    robots: np.ndarray,
    targets: np.ndarray,
    target_velocity: np.ndarray,
    speed: np.ndarray,
    horizon: float,
    oncoming: bool = True,
) -> np.ndarray:
    """Earliest times (s) at which robots (N, 2) at ``speed`` (N,) m/s can meet targets (M, 2)
    moving at constant ``target_velocity`` (M, 2): the least positive root of
    ``|d + v T| = s T`` with ``d`` the target's offset; ``horizon`` where there is none (a
    target that runs away at least as fast as the robot) or it lies further than that.
    Returns (M, N).

    A target as fast as the robot, or faster, is still met when it comes toward the robot
    (``d·v < 0``): the robot waits on its path (the earlier root of the two; for equal speeds
    the one root ``-c/b``). ``oncoming=False`` is the rule before: only a target slower than
    the robot is met (a baseline for ``bench/arrest.py``)."""
    d = targets[:, None, :] - robots[None, :, :]  # (M, N, 2)
    v = np.broadcast_to(target_velocity[:, None, :], d.shape)
    s2 = np.asarray(speed, float)[None, :] ** 2
    a = np.sum(v * v, axis=-1) - s2
    b = 2.0 * np.sum(d * v, axis=-1)
    c = np.sum(d * d, axis=-1)
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        # the earlier root: for a < 0 the one positive root, for a > 0 (b < 0) the first
        # meeting of the two; -c/b when the speeds are equal
        quad = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
        lin = -c / b
    equal = np.abs(a) <= 1e-9 * np.maximum(s2, 1e-12)
    t = np.where(equal, lin, quad)
    ok = (a < -1e-12) & ~equal
    if oncoming:
        ok |= (b < 0) & (equal | (disc >= 0))
    ok &= (disc >= 0) | equal
    ok &= np.isfinite(t) & (t >= 0)
    return np.where(ok, np.minimum(t, horizon), horizon)
