"""Planar geometry on numpy arrays: polygons, poses, angles.

Pure functions, SI units (metres, radians). A polygon is an (n, 2) float array of vertices; a
pose is (x, y, theta) with theta counter-clockwise from the world x axis. Polygons used by the
planners are stored counter-clockwise (positive signed area), so the outward normal of the edge
from p[i] to p[i+1] is the edge direction turned clockwise by 90 degrees.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
TWO_PI = 2.0 * math.pi


def wrap_angle(a: Any) -> Any:
    """Wrap angle(s) in radians to [-pi, pi): the project's one angle wrap.

    A Python or numpy scalar gives a float (fast path: the filters call this per step); an array
    gives an array of the same shape. Re-exported by ``controller.wire`` for the robot side.
    """
    if isinstance(a, float | int):
        return (a + math.pi) % TWO_PI - math.pi
    out = (np.asarray(a, dtype=float) + math.pi) % TWO_PI - math.pi
    return float(out) if out.ndim == 0 else out


def rot(theta: float) -> FloatArray:
    """2x2 rotation matrix for an angle in radians."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def transform(points: ArrayLike, pose: ArrayLike) -> FloatArray:
    """Map body-frame points (n, 2) into the world frame, given the body pose (x, y, theta)."""
    p = np.asarray(points, dtype=float)
    x, y, th = (float(v) for v in np.asarray(pose, dtype=float)[:3])
    return p @ rot(th).T + np.array([x, y])


def inverse_transform(points: ArrayLike, pose: ArrayLike) -> FloatArray:
    """Map world points (n, 2) into the body frame of the pose (x, y, theta)."""
    p = np.asarray(points, dtype=float)
    x, y, th = (float(v) for v in np.asarray(pose, dtype=float)[:3])
    return (p - np.array([x, y])) @ rot(th)


def signed_area(poly: ArrayLike) -> float:
    """Signed area in m^2 (positive for counter-clockwise vertex order)."""
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def ensure_ccw(poly: ArrayLike) -> FloatArray:
    """Return the polygon with counter-clockwise vertex order."""
    p = np.asarray(poly, dtype=float)
    return p[::-1].copy() if signed_area(p) < 0 else p.copy()


def centroid(poly: ArrayLike) -> FloatArray:
    """Area centroid (m) of a simple polygon."""
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = 0.5 * np.sum(cross)
    cx = np.sum((p[:, 0] + q[:, 0]) * cross) / (6.0 * a)
    cy = np.sum((p[:, 1] + q[:, 1]) * cross) / (6.0 * a)
    return np.array([cx, cy])


def polar_moment_per_mass(poly: ArrayLike) -> float:
    """Planar moment of inertia about the area centroid divided by mass (m^2), uniform density."""
    p = np.asarray(poly, dtype=float) - centroid(poly)
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = 0.5 * np.sum(cross)
    ixx = np.sum(cross * (p[:, 1] ** 2 + p[:, 1] * q[:, 1] + q[:, 1] ** 2)) / 12.0
    iyy = np.sum(cross * (p[:, 0] ** 2 + p[:, 0] * q[:, 0] + q[:, 0] ** 2)) / 12.0
    return float((ixx + iyy) / a)


def mean_radius(poly: ArrayLike, n: int = 200) -> float:
    """Mean distance (m) from the area centroid over the polygon's area (n x n grid quadrature).

    The pybullet world puts the object's floor skids at this radius, so spinning the object on
    the floor takes the torque floor_friction * m * g * mean_radius (a uniform-pressure disc).
    """
    p = np.asarray(poly, dtype=float)
    lo, hi = p.min(axis=0), p.max(axis=0)
    u = (np.arange(n) + 0.5) / n
    gx, gy = np.meshgrid(lo[0] + u * (hi[0] - lo[0]), lo[1] + u * (hi[1] - lo[1]))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inside = points_in_polygon(pts, p)
    return float(np.mean(np.linalg.norm(pts[inside] - centroid(p), axis=1)))


def edges(poly: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Edge start points (n, 2) and edge vectors (n, 2); edge i runs from p[i] to p[i+1]."""
    p = np.asarray(poly, dtype=float)
    return p, np.roll(p, -1, axis=0) - p


def outward_normals(poly: ArrayLike) -> FloatArray:
    """Unit outward normals (n, 2) of the edges of a counter-clockwise polygon."""
    _, e = edges(poly)
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _orient(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
        c[..., 0] - a[..., 0]
    )


def segments_intersect(p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray) -> NDArray:
    """Whether segments p1-p2 and q1-q2 intersect (broadcasting, touching counts)."""
    d1 = _orient(q1, q2, p1)
    d2 = _orient(q1, q2, p2)
    d3 = _orient(p1, p2, q1)
    d4 = _orient(p1, p2, q2)
    proper = (d1 * d2 < 0) & (d3 * d4 < 0)

    def on_seg(a, b, c, d):
        return (
            (np.abs(d) <= 1e-12)
            & (np.minimum(a[..., 0], b[..., 0]) - 1e-12 <= c[..., 0])
            & (c[..., 0] <= np.maximum(a[..., 0], b[..., 0]) + 1e-12)
            & (np.minimum(a[..., 1], b[..., 1]) - 1e-12 <= c[..., 1])
            & (c[..., 1] <= np.maximum(a[..., 1], b[..., 1]) + 1e-12)
        )

    touch = on_seg(q1, q2, p1, d1) | on_seg(q1, q2, p2, d2) | on_seg(p1, p2, q1, d3)
    touch = touch | on_seg(p1, p2, q2, d4)
    return proper | touch


def self_intersection(poly: ArrayLike) -> tuple[int, int] | None:
    """The first pair of non-adjacent edges (i, j) that intersect, or None if the polygon is simple.

    Zero-length edges count as a self-intersection of the edge with itself.
    """
    p = np.asarray(poly, dtype=float)
    n = len(p)
    a, e = edges(p)
    b = a + e
    lengths = np.linalg.norm(e, axis=1)
    if np.any(lengths <= 1e-12):
        i = int(np.argmax(lengths <= 1e-12))
        return (i, i)
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))
    i, j = i[keep], j[keep]
    hit = segments_intersect(a[i], b[i], a[j], b[j])
    if np.any(hit):
        k = int(np.argmax(hit))
        return (int(i[k]), int(j[k]))
    return None


def points_in_polygon(points: ArrayLike, poly: ArrayLike) -> NDArray[np.bool_]:
    """Even-odd test for points (m, 2) against a polygon; boundary points may go either way."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=0)
    x = pts[:, 0:1]
    y = pts[:, 1:2]
    yi, yj = p[None, :, 1], q[None, :, 1]
    xi, xj = p[None, :, 0], q[None, :, 0]
    cond = (yi > y) != (yj > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = xi + (y - yi) * (xj - xi) / (yj - yi)
    cross = cond & (x < xint)
    return (np.count_nonzero(cross, axis=1) % 2) == 1


def point_segment_distance(
    points: ArrayLike, a: ArrayLike, b: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Distances (m, s) from points (m, 2) to segments a-b (s, 2), and closest points (m, s, 2)."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))[:, None, :]
    a = np.asarray(a, dtype=float)[None, :, :]
    b = np.asarray(b, dtype=float)[None, :, :]
    ab = b - a
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
    t = np.clip(np.sum((pts - a) * ab, axis=-1) / denom, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(pts - closest, axis=-1), closest


def polygon_boundary_distance(points: ArrayLike, poly: ArrayLike) -> FloatArray:
    """Distance (m) from each point (m, 2) to the polygon boundary."""
    p = np.asarray(poly, dtype=float)
    d, _ = point_segment_distance(points, p, np.roll(p, -1, axis=0))
    return d.min(axis=1)


def polygon_signed_distance(points: ArrayLike, poly: ArrayLike) -> FloatArray:
    """Signed distance (m) to a polygon: negative inside, positive outside."""
    d = polygon_boundary_distance(points, poly)
    inside = points_in_polygon(points, poly)
    return np.where(inside, -d, d)


def discs_hit_polygon(centers: ArrayLike, radius: ArrayLike, poly: ArrayLike) -> NDArray[np.bool_]:
    """Whether discs (centres (m, 2), radii scalar or (m,)) overlap a polygon (interior or edge)."""
    return polygon_signed_distance(centers, poly) < np.asarray(radius, dtype=float)


def disc_gaps(xy: ArrayLike, radii: ArrayLike) -> FloatArray:
    """Gaps between discs, ``|p_i − p_j| − r_i − r_j`` (m), for centres (..., N, 2) and radii
    (N,): an (..., N, N) array with +inf on the diagonal (a disc has no gap to itself)."""
    p = np.asarray(xy, dtype=float)
    r = np.asarray(radii, dtype=float)
    d = np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)
    gap = d - r[:, None] - r[None, :]
    n = p.shape[-2]
    gap[..., np.arange(n), np.arange(n)] = np.inf
    return gap


def min_disc_gap(xy: ArrayLike, radii: ArrayLike) -> FloatArray | float:
    """The smallest gap between any two discs (m), per leading index; inf for fewer than two."""
    gap = disc_gaps(xy, radii)
    out = gap.min(axis=(-2, -1)) if gap.shape[-1] else np.full(gap.shape[:-2], np.inf)
    return float(out) if np.ndim(out) == 0 else out


def discs_touch_static(
    xy: ArrayLike,
    radius: ArrayLike,
    obstacles: list[ArrayLike],
    bounds: ArrayLike | None,
    slack: float = 1e-3,
) -> NDArray[np.bool_]:
    """Which discs (centres (N, 2), radii (N,)) overlap a static obstacle polygon or cross the
    room's walls (``bounds`` [[xmin, ymin], [xmax, ymax]], None: no walls) by more than ``slack``
    metres (a resting contact is not a hit)."""
    p = np.atleast_2d(np.asarray(xy, dtype=float))
    r = np.broadcast_to(np.asarray(radius, dtype=float), (len(p),)) - slack
    hit = np.zeros(len(p), dtype=bool)
    for o in obstacles:
        hit |= polygon_signed_distance(p, o) < r
    if bounds is not None:
        (x0, y0), (x1, y1) = np.asarray(bounds, dtype=float)
        hit |= (p[:, 0] < x0 + r) | (p[:, 0] > x1 - r) | (p[:, 1] < y0 + r) | (p[:, 1] > y1 - r)
    return hit


def polygon_clearance(
    poly: ArrayLike, obstacles: list[ArrayLike], bounds: ArrayLike | None
) -> float:
    """The smallest distance (m) from a polygon to static obstacles and the room's walls
    (``bounds``, None: no walls); negative when it overlaps one (by its deepest vertex).

    Between two polygons the distance is attained at a vertex of one and an edge of the other,
    so vertex-to-polygon signed distances both ways give it exactly (and the penetration depth
    by vertices when they overlap)."""
    p = np.asarray(poly, dtype=float)
    best = math.inf
    for o in obstacles:
        q = np.asarray(o, dtype=float)
        d = min(
            float(polygon_signed_distance(p, q).min()), float(polygon_signed_distance(q, p).min())
        )
        best = min(best, d)
    if bounds is not None:
        (x0, y0), (x1, y1) = np.asarray(bounds, dtype=float)
        walls = np.stack([p[:, 0] - x0, x1 - p[:, 0], p[:, 1] - y0, y1 - p[:, 1]])
        best = min(best, float(walls.min()))
    return best


def convex_hull(points: ArrayLike) -> FloatArray:
    """Counter-clockwise convex hull (monotone chain) of points (m, 2)."""
    pts = np.unique(np.asarray(points, dtype=float), axis=0)
    if len(pts) < 3:
        return pts
    seq = pts[np.lexsort((pts[:, 1], pts[:, 0]))].tolist()  # Python floats: the same
    # arithmetic as _orient on arrays, without numpy's per-element overhead (a tick's hot loop)

    def half(seq: list[list[float]]) -> list[list[float]]:
        out: list[list[float]] = []
        for p in seq:
            while len(out) >= 2:
                a, b = out[-2], out[-1]
                if (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) > 0:
                    break
                out.pop()
            out.append(p)
        return out

    lower = half(seq)
    upper = half(seq[::-1])
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def _crosses_convex(a: FloatArray, b: FloatArray, hull: FloatArray) -> bool:
    """Whether the open segment a-b passes through the interior of a convex CCW polygon."""
    mid = np.linspace(a, b, 9)[1:-1]
    if np.any(points_in_polygon(mid, hull) & (polygon_boundary_distance(mid, hull) > 1e-9)):
        return True
    return False


def distance_around_convex(starts: ArrayLike, goals: ArrayLike, hull: ArrayLike) -> FloatArray:
    """Shortest path lengths (S, G) m from points to points that may not cross the interior of a
    convex CCW polygon (a visibility graph through its vertices). Points inside it are treated as
    on its boundary (they leave along the straight line)."""
    from scipy.sparse.csgraph import shortest_path

    h = np.asarray(hull, dtype=float)
    s = np.atleast_2d(np.asarray(starts, dtype=float))
    g = np.atleast_2d(np.asarray(goals, dtype=float))
    n_h = len(h)
    grown = h + 1e-6 * (h - h.mean(axis=0))  # vertices just outside: their chords stay inside
    nodes = np.vstack([grown, s, g])
    n = len(nodes)
    w = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            if i < n_h and j < n_h and abs(i - j) not in (1, n_h - 1):
                continue  # a chord of the hull crosses it
            if not _crosses_convex(nodes[i], nodes[j], h):
                w[i, j] = w[j, i] = float(np.linalg.norm(nodes[i] - nodes[j]))
    dist = shortest_path(w, method="D", directed=False, indices=range(n_h, n_h + len(s)))
    out = dist[:, n_h + len(s) :]
    straight = np.linalg.norm(s[:, None] - g[None], axis=-1)
    return np.where(np.isfinite(out), out, straight)


def vertex_distance(points: ArrayLike, polygon: ArrayLike) -> FloatArray:
    """Each point's distance to the polygon's nearest vertex (m)."""
    d = np.asarray(points, float)[:, None, :] - np.asarray(polygon, float)[None]
    return np.sqrt((d * d).sum(-1)).min(axis=1)
