"""An independent check of object routes with shapely (for the route tests and bench).

Nothing here uses the planner's own geometry: a straight move's swept area is built exactly
(the polygon at both ends and each edge swept, unioned), a turn in place is sampled so that no
point of the polygon is farther than 1e-4 m from a sample, and that bound is given back.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from controller import geometry


def clearance(shapes, obstacles, bounds) -> np.ndarray | float:
    """Distance (m) from shapes (one or an array) to the nearest obstacle or wall (-1: outside
    the room)."""
    (x0, y0), (x1, y1) = bounds
    room = shapely.box(x0, y0, x1, y1)
    g = np.atleast_1d(np.asarray(shapes, dtype=object))
    d = shapely.distance(room.exterior, g)
    for o in obstacles:
        d = np.minimum(d, shapely.distance(shapely.Polygon(o), g))
    d = np.where(shapely.contains(room, g), d, -1.0)
    return float(d[0]) if np.ndim(shapes) == 0 else d


def placed(poly: np.ndarray, pose) -> shapely.Polygon:
    return shapely.Polygon(geometry.transform(poly, pose))


def swept_translation(poly: np.ndarray, a, b) -> shapely.Geometry:
    """Exact swept area of the polygon moved straight from pose a to pose b (same heading)."""
    pa, pb = geometry.transform(poly, a), geometry.transform(poly, b)
    parts = [shapely.Polygon(pa), shapely.Polygon(pb)]
    for i in range(len(pa)):
        j = (i + 1) % len(pa)
        parts.append(shapely.MultiPoint([pa[i], pa[j], pb[i], pb[j]]).convex_hull)
    return shapely.union_all(parts)


def turn_centre(a, b) -> np.ndarray:
    """The point that stays put in the rigid motion from pose a to pose b (a pure turn)."""
    ra, rb = geometry.rot(a[2]), geometry.rot(b[2])
    m = np.eye(2) - rb @ ra.T
    return np.linalg.solve(m, np.asarray(b[:2]) - rb @ ra.T @ np.asarray(a[:2]))


def step_clearance(poly, a, b, obstacles, bounds) -> float:
    """Clearance of the move a -> b, which must be one straight move or one turn in place.

    Turns are sampled so that no point of the polygon is farther than 1e-4 m from a sample; the
    value returned is the sampled clearance minus that bound (never above the truth).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    dth = float(geometry.wrap_angle(b[2] - a[2]))
    if abs(dth) < 1e-12:
        return clearance(swept_translation(poly, a, b), obstacles, bounds)
    c = turn_centre(a, b)
    # a turn in place: every vertex keeps its distance to the centre
    pa, pb = geometry.transform(poly, a), geometry.transform(poly, b)
    assert np.allclose(np.linalg.norm(pa - c, axis=1), np.linalg.norm(pb - c, axis=1), atol=1e-9)
    rho = float(np.max(np.linalg.norm(pa - c, axis=1)))
    n = max(2, int(math.ceil(abs(dth) * rho / 2e-4)))
    th = a[2] + np.linspace(0.0, 1.0, n + 1) * dth
    rel = np.asarray(a[:2]) - c
    cs, sn = np.cos(th - a[2]), np.sin(th - a[2])
    origin = c + np.stack([cs * rel[0] - sn * rel[1], sn * rel[0] + cs * rel[1]], 1)
    pts = origin[:, None, :] + np.einsum("nij,vj->nvi", _rots(th), poly)
    return float(np.min(clearance(shapely.polygons(pts), obstacles, bounds))) - 1e-4


def _rots(th: np.ndarray) -> np.ndarray:
    c, s = np.cos(th), np.sin(th)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def assert_route_clear(res, poly, radius, obstacles, bounds, start, goal) -> None:
    """The route starts and ends exactly, and no move brings the object within the ring."""
    wp = res.waypoints
    assert np.allclose(wp[0], start) and np.allclose(wp[-1], goal)
    ring = 2.0 * radius
    for a, b in zip(wp[:-1], wp[1:], strict=True):
        d = step_clearance(poly, a, b, obstacles, bounds)
        assert d >= ring - 1e-9, (a, b, d)


def route_clearance(res, poly, obstacles, bounds) -> float:
    """The least clearance (m) of any move of a route (``step_clearance``)."""
    wp = res.waypoints
    pairs = zip(wp[:-1], wp[1:], strict=True)
    return min(step_clearance(poly, a, b, obstacles, bounds) for a, b in pairs)
