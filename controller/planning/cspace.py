"""Configuration spaces: the carried object's (x, y, theta) lattice and a robot disc's (x, y) grid.

Pure numpy/scipy/shapely, no I/O. The world inside ``bounds`` is cut into square cells of side
``resolution`` (m); cell ``(iy, ix)`` has its centre at ``(x0 + (ix + 0.5) res, y0 + (iy + 0.5)
res)``. Everything outside the bounds is an obstacle (the walls).

**The object's lattice** (Yamashita et al. §3, with a uniform grid in place of the octree). The
*footprint* is the object polygon grown by the robot ring: a pose collides when the polygon comes
closer than ``ring = 2 * robot_radius`` to an obstacle or to a wall. The lattice positions are
those of a *reference point* of the object, the centre of the polygon's smallest enclosing circle
(so a turn in place sweeps as little as possible and the heading quantization moves no point of
the object by more than ``rho * pi / K``); lattice state ``(k, iy, ix)`` is the exact pose with the
reference point at the centre of cell (iy, ix) and heading ``k * 2 pi / K``. Moves: a one-cell
step in one of 8 directions at a fixed heading, or one heading bin in place.

Which states are free is decided **exactly**, fast:

1. A distance raster: each cell centre's distance to the obstacles and the walls (exact).
2. Three FFT correlations of thresholded rasters with the footprint rasterized at each heading
   classify every state as *surely colliding* (a point of the footprint lies within the ring of
   an obstacle), *surely free* (the footprint, grown by half a cell diagonal, misses every cell
   within ring + half a cell diagonal of an obstacle) or *uncertain* (a thin shell).
3. The uncertain states are decided by an exact polygon test (shapely 2, vectorised, the
   obstacles near each footprint found by an STR tree).

The same correlations mark the states whose clearance exceeds the ring by the largest sweep
margin of a move (``max(res / sqrt 2, 2 rho sin(pi / 2K))``): a move between two such states is
free with no further test. Every other move is checked exactly, lazily, when the search first
uses it (:meth:`ObjectCSpace.moves_free`), by :class:`FootprintChecker`'s swept-footprint tests:
a translation or rotation between two free poses collides exactly when a vertex of the footprint
(moving along a segment or an arc) comes within the ring of an obstacle edge, or an obstacle
vertex (moving the other way relative to the object) within the ring of a footprint edge;
only the (vertex, edge) pairs whose bounding boxes come within the ring are computed (the others
cannot decide the test). Nothing is conservative beyond floating-point tolerance (1e-12 m), so
the lattice loses only what its spacing loses: a way whose clearance beyond the ring is a cell
or more on each side is found at the default 0.1 m x 36 headings, also through doorways turned
off the lattice's directions and heading bins (checked in ``tests/unit/test_route.py``); the
heading quantization moves no point by more than ``rho pi / K`` (0.06 m for the shipped 1 m
crate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sfft
from scipy import ndimage

from controller import geometry
from controller.config import ConfigError

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: 8-connected moves as (dx, dy) in cells: E, NE, N, NW, W, SW, S, SE (counter-clockwise from +x).
MOVES_8 = np.array(
    [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)], dtype=int
)
#: Lattice move numbers past the 8 translations: one heading bin up (+), one down (-).
TURN_UP, TURN_DOWN = 8, 9
_TOL = 1e-12
#: The block of moves checked together on a cache miss: heading bins and cells either side.
_BLOCK = (1, 3)


class CSpaceError(ConfigError):
    """Bad C-space input (bounds, resolution, polygon, radius); ``path`` names the parameter."""

    def __init__(self, path: str, message: str):
        super().__init__("", path, message)


@dataclass(frozen=True, eq=False)
class GridFrame:
    """The cell grid over the world bounds: origin (m), resolution (m), size in cells."""

    x0: float
    y0: float
    resolution: float
    nx: int
    ny: int

    @staticmethod
    def over(bounds: ArrayLike, resolution: float) -> GridFrame:
        """The grid over ``bounds`` [[xmin, ymin], [xmax, ymax]] (m), cells of ``resolution`` m."""
        b = _bounds(bounds)
        if not (resolution > 0 and math.isfinite(resolution)):
            raise CSpaceError(
                "resolution", f"expected a positive number of metres, got {resolution!r}"
            )
        (x0, y0), (x1, y1) = b
        nx = int(math.ceil((x1 - x0) / resolution - 1e-9))
        ny = int(math.ceil((y1 - y0) / resolution - 1e-9))
        return GridFrame(float(x0), float(y0), float(resolution), nx, ny)

    def cell_of(self, xy: ArrayLike) -> tuple[int, int] | None:
        """(iy, ix) of the cell holding the point (m), or None outside the grid."""
        x, y = (float(v) for v in np.asarray(xy, dtype=float)[:2])
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        ix = int(math.floor((x - self.x0) / self.resolution))
        iy = int(math.floor((y - self.y0) / self.resolution))
        if 0 <= ix < self.nx and 0 <= iy < self.ny:
            return iy, ix
        return None

    def centers(self) -> tuple[FloatArray, FloatArray]:
        """Cell-centre coordinates (m): xs (nx,), ys (ny,)."""
        r = self.resolution
        return self.x0 + (np.arange(self.nx) + 0.5) * r, self.y0 + (np.arange(self.ny) + 0.5) * r

    def center(self, iy: int, ix: int) -> tuple[float, float]:
        """Centre (m) of cell (iy, ix)."""
        r = self.resolution
        return self.x0 + (ix + 0.5) * r, self.y0 + (iy + 0.5) * r


def _bounds(bounds: ArrayLike) -> FloatArray:
    try:
        b = np.asarray(bounds, dtype=float).reshape(2, 2)
    except (TypeError, ValueError) as exc:
        raise CSpaceError(
            "bounds", f"expected [[xmin, ymin], [xmax, ymax]], got {bounds!r}"
        ) from exc
    (x0, y0), (x1, y1) = b
    if not (np.all(np.isfinite(b)) and x1 > x0 and y1 > y0):
        raise CSpaceError(
            "bounds", f"expected [[xmin, ymin], [xmax, ymax]] with max > min, got {b.tolist()}"
        )
    return b


def _polygon(poly: ArrayLike, path: str) -> FloatArray:
    try:
        p = np.asarray(poly, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CSpaceError(path, f"expected an (n>=3, 2) polygon, got {poly!r}") from exc
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
        raise CSpaceError(path, f"expected an (n>=3, 2) polygon, got shape {p.shape}")
    if not np.all(np.isfinite(p)) or abs(geometry.signed_area(p)) < 1e-12:
        raise CSpaceError(path, "expected a polygon of finite vertices and non-zero area")
    return geometry.ensure_ccw(p)


# --------------------------------------------------------------------------- exact geometry


def _orient(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
        c[..., 0] - a[..., 0]
    )


def _point_segment(x: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance from points x to segments a-b (broadcasting over the leading axes)."""
    ab = b - a
    den = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
    t = np.clip(np.sum((x - a) * ab, axis=-1) / den, 0.0, 1.0)
    return np.linalg.norm(x - a - t[..., None] * ab, axis=-1)


def segment_distance(p0: ArrayLike, p1: ArrayLike, q0: ArrayLike, q1: ArrayLike) -> FloatArray:
    """Distance (m) between segments p0-p1 and q0-q1 (broadcasting; 0 where they cross)."""
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    d = np.minimum(
        np.minimum(_point_segment(p0, q0, q1), _point_segment(p1, q0, q1)),
        np.minimum(_point_segment(q0, p0, p1), _point_segment(q1, p0, p1)),
    )
    cross = (_orient(p0, p1, q0) * _orient(p0, p1, q1) < 0) & (
        _orient(q0, q1, p0) * _orient(q0, q1, p1) < 0
    )
    return np.where(cross, 0.0, d)


def _in_arc(vec: FloatArray, start: FloatArray, sweep: FloatArray) -> BoolArray:
    ang = np.arctan2(vec[..., 1], vec[..., 0])
    return np.mod(ang - start, 2.0 * math.pi) <= sweep + 1e-12


def arc_segment_distance(
    center: ArrayLike,
    radius: ArrayLike,
    start: ArrayLike,
    sweep: ArrayLike,
    q0: ArrayLike,
    q1: ArrayLike,
) -> FloatArray:
    """Distance (m) between circular arcs and segments q0-q1 (broadcasting).

    Arc: centre (..., 2), radius (m), from angle ``start`` through the signed angle ``sweep``
    (rad, |sweep| <= 2 pi). Exact: the minimum over the arc's end points to the segment, the
    segment's end points and its foot of perpendicular to the arc (where their direction lies in
    the arc's range) and 0 where the segment crosses the arc.
    """
    c, q0, q1 = (np.asarray(v, dtype=float) for v in (center, q0, q1))
    rad = np.asarray(radius, dtype=float)
    a0 = np.asarray(start, dtype=float)
    sw = np.asarray(sweep, dtype=float)
    a0 = np.where(sw < 0, a0 + sw, a0)
    sw = np.abs(sw)
    e0 = c + rad[..., None] * np.stack([np.cos(a0), np.sin(a0)], axis=-1)
    e1 = c + rad[..., None] * np.stack([np.cos(a0 + sw), np.sin(a0 + sw)], axis=-1)
    best = np.minimum(_point_segment(e0, q0, q1), _point_segment(e1, q0, q1))
    for x in (q0, q1):
        v = x - c
        cand = np.abs(np.linalg.norm(v, axis=-1) - rad)
        best = np.where(_in_arc(v, a0, sw), np.minimum(best, cand), best)
    d = q1 - q0
    dd = np.maximum(np.sum(d * d, axis=-1), 1e-300)
    f = q0 - c
    t = -np.sum(f * d, axis=-1) / dd
    foot = f + t[..., None] * d
    nf = np.linalg.norm(foot, axis=-1)
    ok = (t > 0) & (t < 1) & (nf >= rad) & _in_arc(foot, a0, sw)
    best = np.where(ok, np.minimum(best, nf - rad), best)
    # crossings of the segment with the circle: |f + t d|^2 = rad^2
    b = np.sum(f * d, axis=-1)
    disc = b * b - dd * (np.sum(f * f, axis=-1) - rad * rad)
    root = np.sqrt(np.maximum(disc, 0.0))
    for sgn in (-1.0, 1.0):
        tc = (-b + sgn * root) / dd
        pt = f + tc[..., None] * d
        hit = (disc >= 0) & (tc >= 0) & (tc <= 1) & _in_arc(pt, a0, sw)
        best = np.where(hit, 0.0, best)
    return best


class FootprintChecker:
    """Exact collision tests of the grown footprint; poses are of the reference point.

    polygon: the object polygon in the reference frame (CCW, m); ring: the clearance it needs
    (m, twice the robot radius); a pose collides when the polygon comes closer than ``ring`` to
    an obstacle or to a wall (touching the ring is allowed, to 1e-12 m).
    """

    def __init__(
        self, bounds: ArrayLike, obstacles: list[FloatArray], polygon: FloatArray, ring: float
    ):
        b = _bounds(bounds)
        self.box = (float(b[0, 0]), float(b[0, 1]), float(b[1, 0]), float(b[1, 1]))
        self.poly = np.asarray(polygon, dtype=float)
        self.ring = float(ring)
        self.req = max(self.ring, 1e-9)
        self.rho = float(np.max(np.linalg.norm(self.poly, axis=1)))
        self.obstacles = [np.asarray(o, dtype=float) for o in obstacles]
        x0, y0, x1, y1 = self.box
        room = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        seg_a, seg_b, owner, verts, vowner = [], [], [], [], []
        for i, p in enumerate([*self.obstacles, room]):
            seg_a.append(p)
            seg_b.append(np.roll(p, -1, axis=0))
            owner.append(np.full(len(p), i if i < len(self.obstacles) else -1))
            verts.append(p)
            vowner.append(owner[-1])
        self.seg_a = np.concatenate(seg_a)
        self.seg_b = np.concatenate(seg_b)
        self.seg_owner = np.concatenate(owner)
        self.verts = np.concatenate(verts)
        self.vert_owner = np.concatenate(vowner)
        self._shapes = [shapely.Polygon(o) for o in self.obstacles]
        self._tree = shapely.STRtree(self._shapes) if self._shapes else None
        self._polar = np.arctan2(self.poly[:, 1], self.poly[:, 0])
        self._radius = np.linalg.norm(self.poly, axis=1)

    # -- poses --------------------------------------------------------------------------------
    def world(self, poses: ArrayLike) -> FloatArray:
        """Footprint vertices (N, n, 2) at reference poses (N, 3)."""
        p = np.atleast_2d(np.asarray(poses, dtype=float))
        c, s = np.cos(p[:, 2])[:, None], np.sin(p[:, 2])[:, None]
        x = p[:, None, 0] + c * self.poly[None, :, 0] - s * self.poly[None, :, 1]
        y = p[:, None, 1] + s * self.poly[None, :, 0] + c * self.poly[None, :, 1]
        return np.stack([x, y], axis=-1)

    def _walls_ok(self, w: FloatArray) -> BoolArray:
        x0, y0, x1, y1 = self.box
        r = self.req - _TOL
        return (
            (w[..., 0].min(axis=-1) >= x0 + r)
            & (w[..., 0].max(axis=-1) <= x1 - r)
            & (w[..., 1].min(axis=-1) >= y0 + r)
            & (w[..., 1].max(axis=-1) <= y1 - r)
        )

    def poses_free(self, poses: ArrayLike, chunk: int = 50_000) -> BoolArray:
        """Exact test of reference poses (N, 3): True where the grown footprint is clear."""
        p = np.atleast_2d(np.asarray(poses, dtype=float))
        out = np.zeros(len(p), dtype=bool)
        for i in range(0, len(p), chunk):
            w = self.world(p[i : i + chunk])
            ok = self._walls_ok(w)
            if self._tree is not None and ok.any():
                # within the ring of some obstacle (an STR tree finds the near ones; the same
                # answer as against their union, faster)
                polys = shapely.polygons(w[ok])
                hit, _ = self._tree.query(polys, predicate="dwithin", distance=self.req - _TOL)
                near = np.zeros(len(polys), dtype=bool)
                near[hit] = True
                ok[ok] = ~near
            out[i : i + chunk] = ok
        return out

    def clearance(self, pose: ArrayLike) -> tuple[float, str]:
        """Distance (m) from the object polygon at a reference pose to the nearest obstacle or
        wall, and what that is ("obstacles[i]" or "the walls")."""
        w = self.world(pose)[0]
        x0, y0, x1, y1 = self.box
        best = float(min(w[:, 0].min() - x0, x1 - w[:, 0].max()))
        best = min(best, float(w[:, 1].min() - y0), float(y1 - w[:, 1].max()))
        what = "the walls (world bounds)"
        poly = shapely.Polygon(w)
        for i, o in enumerate(self._shapes):
            d = float(shapely.distance(poly, o))
            if d < best:
                best, what = d, f"obstacles[{i}]"
        return best, what

    def overlap(self, pose: ArrayLike) -> float:
        """Area (m²) of the object polygon at a reference pose inside obstacles or beyond the
        walls: 0 when it only touches them (:meth:`clearance` is 0 for both)."""
        w = self.world(pose)[0]
        poly = shapely.Polygon(w)
        x0, y0, x1, y1 = self.box
        area = float(poly.area - poly.intersection(shapely.box(x0, y0, x1, y1)).area)
        for o in self._shapes:
            area += float(poly.intersection(o).area)
        return area

    def pusher_room(
        self, pose: ArrayLike, direction: ArrayLike, radius: float, cone: float
    ) -> bool:
        """Whether a robot of ``radius`` fits against the object at a reference pose where it
        can push it along ``direction`` (world, unit): touching a face whose inward normal is
        within ``cone`` rad of it, at a quarter, the middle or three quarters of the face, its
        disc inside the walls and clear of the obstacles and of the object's other faces."""
        w = self.world(pose)[0]
        u = np.asarray(direction, dtype=float)[:2]
        edge = np.roll(w, -1, axis=0) - w
        length = np.maximum(np.linalg.norm(edge, axis=1), 1e-12)
        out = np.stack([edge[:, 1], -edge[:, 0]], 1) / length[:, None]  # outward: CCW polygon
        x0, y0, x1, y1 = self.box
        body = shapely.Polygon(w)
        for i in np.flatnonzero(-(out @ u) >= math.cos(cone) - 1e-9):
            for f in (0.25, 0.5, 0.75):
                c = w[i] + f * edge[i] + radius * out[i]
                if not (x0 + radius <= c[0] <= x1 - radius and y0 + radius <= c[1] <= y1 - radius):
                    continue
                disc = shapely.Point(c)
                if body.distance(disc) < radius - 1e-6:
                    continue  # another face of the object is in the way (a notch)
                if all(float(shapely.distance(disc, o)) >= radius - _TOL for o in self._shapes):
                    return True
        return False

    # -- sweeps -------------------------------------------------------------------------------
    def _near(self, centers: FloatArray, reach: float) -> tuple[BoolArray, BoolArray]:
        lo = centers.min(axis=0) - reach
        hi = centers.max(axis=0) + reach
        smin = np.minimum(self.seg_a, self.seg_b)
        smax = np.maximum(self.seg_a, self.seg_b)
        seg = np.all((smax >= lo) & (smin <= hi), axis=1)
        vert = np.all((self.verts >= lo) & (self.verts <= hi), axis=1)
        return seg, vert

    def translations_free(self, poses: ArrayLike, steps: ArrayLike) -> BoolArray:
        """Whether each translation from reference pose (N, 3) by step (N, 2) m, heading fixed,
        keeps the ring clear. Both end poses must be free (then this test is exact)."""
        v = np.atleast_2d(np.asarray(steps, dtype=float))
        longest = float(np.max(np.linalg.norm(v, axis=1))) if v.size else 0.0
        return self._sweeps_free(poses, v, longest, self._trail_distance)

    def rotations_free(self, poses: ArrayLike, turns: ArrayLike) -> BoolArray:
        """Whether each turn in place of reference pose (N, 3) by the signed angle (N,) rad
        keeps the ring clear. Both end poses must be free (then this test is exact)."""
        dt = np.atleast_1d(np.asarray(turns, dtype=float))
        return self._sweeps_free(poses, dt, 0.0, self._arc_distance)

    def _sweeps_free(self, poses: ArrayLike, amount, longest: float, distance) -> BoolArray:
        """Common part of the sweep tests: only the obstacle edges and vertices within reach of
        the batch take part; ``distance(p, amount, edges, vertices)`` gives per move the least
        distance between a moving vertex and a fixed edge, either way round."""
        p = np.atleast_2d(np.asarray(poses, dtype=float))
        if len(p) == 0:
            return np.zeros(0, dtype=bool)
        seg, vert = self._near(p[:, :2], self.rho + self.req + longest + 1e-9)
        if not seg.any():
            return np.ones(len(p), dtype=bool)
        d = distance(p, amount, (self.seg_a[seg], self.seg_b[seg]), self.verts[vert])
        return d >= self.req - _TOL

    def _trail_distance(self, p, v, edges, verts) -> FloatArray:
        """Per translation, the least distance between a vertex trail and an edge, over the
        (trail, edge) pairs whose boxes come within the ring (the others are farther: they
        cannot decide the test), each pair computed as :func:`segment_distance` does."""
        w = self.world(p)  # (N, n, 2)
        w1 = w + v[:, None]
        sa, sb = edges
        d = np.full(len(p), np.inf)
        # footprint vertices along their straight trails against obstacle and wall edges
        i, a, b = _near_pairs(
            (np.minimum(w, w1), np.maximum(w, w1)),
            (np.minimum(sa, sb)[None], np.maximum(sa, sb)[None]),
            self.req,
        )
        if len(i):
            np.minimum.at(d, i, segment_distance(w[i, a], w1[i, a], sa[b], sb[b]))
        if len(verts):  # obstacle vertices moving the other way against the footprint edges
            fa, fb = w, np.roll(w, -1, axis=1)
            o1 = verts[None] - v[:, None]  # (N, V, 2)
            i, a, b = _near_pairs(
                (np.minimum(verts[None], o1), np.maximum(verts[None], o1)),
                (np.minimum(fa, fb), np.maximum(fa, fb)),
                self.req,
            )
            if len(i):
                dd = segment_distance(verts[a], o1[i, a], fa[i, b], fb[i, b])
                np.minimum.at(d, i, dd)
        return d

    def _arc_distance(self, p, dt, edges, verts) -> FloatArray:
        """As :meth:`_trail_distance` for turns in place (arcs, by
        :func:`arc_segment_distance`)."""
        c = p[:, :2]
        sa, sb = edges
        d = np.full(len(p), np.inf)
        # footprint vertices along arcs about the reference point against the edges
        start = p[:, 2:3] + self._polar[None]  # (N, n)
        rad = np.broadcast_to(self._radius[None], start.shape)
        i, a, b = _near_pairs(
            _arc_boxes(c, rad, start, dt),
            (np.minimum(sa, sb)[None], np.maximum(sa, sb)[None]),
            self.req,
        )
        if len(i):
            dd = arc_segment_distance(c[i], rad[i, a], start[i, a], dt[i], sa[b], sb[b])
            np.minimum.at(d, i, dd)
        if len(verts):  # obstacle vertices turning the other way against the footprint edges
            w = self.world(p)
            fa, fb = w, np.roll(w, -1, axis=1)  # (N, n, 2)
            rel = verts[None] - p[:, None, :2]  # (N, V, 2)
            rad = np.linalg.norm(rel, axis=-1)
            ang = np.arctan2(rel[..., 1], rel[..., 0])
            i, a, b = _near_pairs(
                _arc_boxes(c, rad, ang, -dt), (np.minimum(fa, fb), np.maximum(fa, fb)), self.req
            )
            if len(i):
                dd = arc_segment_distance(c[i], rad[i, a], ang[i, a], -dt[i], fa[i, b], fb[i, b])
                np.minimum.at(d, i, dd)
        return d


def _near_pairs(boxes_a, boxes_b, reach: float) -> tuple[NDArray[np.intp], ...]:
    """(i, a, b) of the pairs of boxes (lo, hi) that come within ``reach`` of each other:
    boxes_a (N, A, 2) against boxes_b (N or 1, B, 2), per move i. A pair left out is more than
    ``reach`` apart along x or y."""
    (la, ha), (lb, hb) = boxes_a, boxes_b
    la, ha, lb, hb = la[:, :, None], ha[:, :, None], lb[:, None], hb[:, None]
    near = (la[..., 0] <= hb[..., 0] + reach) & (ha[..., 0] + reach >= lb[..., 0])
    near &= (la[..., 1] <= hb[..., 1] + reach) & (ha[..., 1] + reach >= lb[..., 1])
    return np.nonzero(near)


def _arc_boxes(c: FloatArray, rad: FloatArray, start: FloatArray, sweep: FloatArray):
    """Boxes (lo, hi) (N, A, 2) holding the arcs about centres c (N, 2) of radii and start
    angles (N, A) through the signed angles sweep (N,) (|sweep| <= pi): the chord's box grown
    by the sagitta (and 1e-9 m)."""
    a1 = start + sweep[:, None]
    e0 = c[:, None] + rad[..., None] * np.stack([np.cos(start), np.sin(start)], axis=-1)
    e1 = c[:, None] + rad[..., None] * np.stack([np.cos(a1), np.sin(a1)], axis=-1)
    sag = (rad * (1.0 - np.cos(np.abs(sweep)[:, None] / 2.0)) + 1e-9)[..., None]
    return np.minimum(e0, e1) - sag, np.maximum(e0, e1) + sag


# --------------------------------------------------------------------------- rasters


def clearance_raster(
    frame: GridFrame,
    box: tuple[float, float, float, float],
    obstacles: list[FloatArray],
    cap: float,
) -> FloatArray:
    """Distance (m) from each cell centre (ny, nx) to the obstacles and the walls of ``box``
    (xmin, ymin, xmax, ymax), capped at ``cap``; negative inside an obstacle or outside the box.
    """
    xs, ys = frame.centers()
    x0, y0, x1, y1 = box
    d = np.minimum.outer(np.minimum(ys - y0, y1 - ys), np.minimum(xs - x0, x1 - xs))
    d = np.minimum(d, cap)
    r = frame.resolution
    for p in obstacles:
        lo = np.floor((p.min(axis=0) - cap - [frame.x0, frame.y0]) / r).astype(int)
        hi = np.ceil((p.max(axis=0) + cap - [frame.x0, frame.y0]) / r).astype(int) + 1
        ix0, iy0 = max(lo[0], 0), max(lo[1], 0)
        ix1, iy1 = min(hi[0], frame.nx), min(hi[1], frame.ny)
        if ix0 >= ix1 or iy0 >= iy1:
            continue
        gx, gy = np.meshgrid(xs[ix0:ix1], ys[iy0:iy1])
        sd = geometry.polygon_signed_distance(np.stack([gx.ravel(), gy.ravel()], axis=1), p)
        win = d[iy0:iy1, ix0:ix1]
        np.minimum(win, sd.reshape(gx.shape), out=win)
    return d


def footprint_kernels(
    polygon: ArrayLike, resolution: float, heading_bins: int, grow: float
) -> tuple[BoolArray, int]:
    """The footprint rasterized per heading: (K, 2m+1, 2m+1) bool kernels and the half size m.

    ``kernel[k, m + dy, m + dx]`` is true when the centre of the cell at offset (dx, dy) cells
    lies within ``grow`` m of the polygon (reference frame) turned to heading ``k 2 pi / K``
    (``grow = 0``: inside it or on its boundary).
    """
    poly = np.asarray(polygon, dtype=float)
    rho = float(np.max(np.linalg.norm(poly, axis=1)))
    m = int(math.ceil((rho + grow) / resolution)) + 1
    f = np.arange(-m, m + 1) * resolution
    gx, gy = np.meshgrid(f, f)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    k_bins = int(heading_bins)
    out = np.zeros((k_bins, 2 * m + 1, 2 * m + 1), dtype=bool)
    for k in range(k_bins):
        q = geometry.transform(poly, (0.0, 0.0, 2.0 * math.pi * k / k_bins))
        out[k] = (geometry.polygon_signed_distance(pts, q) <= grow + 1e-13).reshape(gx.shape)
    return out, m


def _correlate_any(masks: list[BoolArray], kernels: BoolArray, m: int) -> list[BoolArray]:
    """For each (ny, nx) mask (outside the grid counts as set): (K, ny, nx), true where the
    kernel of heading k placed on the cell covers a set cell. One FFT per mask, per kernel."""
    ny, nx = masks[0].shape
    shape = (sfft.next_fast_len(ny + 4 * m, real=True), sfft.next_fast_len(nx + 4 * m, real=True))
    fms = [
        sfft.rfft2(np.pad(mk, m, constant_values=True).astype(np.float32), shape) for mk in masks
    ]
    k_bins = len(kernels)
    outs = [np.empty((k_bins, ny, nx), dtype=bool) for _ in masks]
    step = 12
    for a in range(0, k_bins, step):
        fk = sfft.rfft2(kernels[a : a + step, ::-1, ::-1].astype(np.float32), shape)
        for fm, out in zip(fms, outs, strict=True):
            full = sfft.irfft2(fm[None] * fk, shape)
            out[a : a + step] = full[:, 2 * m : 2 * m + ny, 2 * m : 2 * m + nx] > 0.5
    return outs


def _label_with_wrap(free: BoolArray) -> NDArray[np.int32]:
    """Connected components of the (K, ny, nx) free states under the lattice moves.

    Moves: 8-connected within a heading layer, and one heading step in place (wrapping from the
    last bin to the first). Label 0 = occupied.
    """
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[1] = True
    structure[0, 1, 1] = structure[2, 1, 1] = True
    labels, n = ndimage.label(free, structure=structure)
    k_bins = free.shape[0]
    if k_bins > 2 and n > 1:
        both = free[0] & free[-1]
        a, b = labels[0][both], labels[-1][both]
        parent = np.arange(n + 1)

        def find(i: int) -> int:
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        for u, v in set(zip(a.tolist(), b.tolist(), strict=True)):
            ru, rv = find(u), find(v)
            if ru != rv:
                parent[max(ru, rv)] = min(ru, rv)
        roots = np.array([find(i) for i in range(n + 1)])
        labels = roots[labels]
    return labels.astype(np.int32)


# --------------------------------------------------------------------------- the object


def reference_point(polygon: ArrayLike) -> FloatArray:
    """Centre (m, object frame) of the polygon's smallest enclosing circle."""
    c = shapely.minimum_bounding_circle(shapely.Polygon(np.asarray(polygon, dtype=float)))
    if c.geom_type == "Point":
        return np.array([c.x, c.y])
    return np.asarray(c.centroid.coords[0], dtype=float)


@dataclass(frozen=True, eq=False)
class ObjectCSpace:
    """The carried object's (x, y, theta) lattice: build once with :func:`build_object_cspace`.

    ``free[k, iy, ix]``: the lattice state (reference point at the cell's centre, heading
    ``k 2 pi / K``) is collision-free, decided exactly. ``margin_free``: its clearance exceeds the
    ring by the sweep margin, so a move to another such state needs no test. Poses passed in and
    out are of the object frame (as ``object.start``); :meth:`ref_pose` and :meth:`frame_pose`
    convert to and from the reference point's pose. Checked moves are cached (the cache is the
    only mutable part; it is shared by every planner on this C-space).
    """

    frame: GridFrame
    heading_bins: int
    free: BoolArray
    margin_free: BoolArray
    footprint: FloatArray
    ref: FloatArray
    robot_radius: float
    checker: FootprintChecker
    counts: dict[str, int]
    _moves: dict[int, bool] = field(default_factory=dict, repr=False)

    @property
    def occupied(self) -> BoolArray:
        """Colliding lattice states (K, ny, nx)."""
        return ~self.free

    @property
    def step(self) -> float:
        """Heading bin width (rad)."""
        return 2.0 * math.pi / self.heading_bins

    @cached_property
    def labels(self) -> NDArray[np.int32]:
        """Connected components of the free states under the lattice moves (0 = occupied)."""
        return _label_with_wrap(self.free)

    def heading_of(self, k: int) -> float:
        """Heading (rad, in [-pi, pi)) of bin k."""
        return float(geometry.wrap_angle(k * self.step))

    def bin_of(self, theta: float) -> int:
        """Nearest heading bin of an angle (rad)."""
        return int(round(float(theta) / self.step)) % self.heading_bins

    def ref_pose(self, pose: ArrayLike) -> FloatArray:
        """The reference point's pose (x, y, theta) for an object-frame pose."""
        p = np.asarray(pose, dtype=float)[:3]
        c, s = math.cos(p[2]), math.sin(p[2])
        rx, ry = self.ref
        return np.array([p[0] + c * rx - s * ry, p[1] + s * rx + c * ry, p[2]])

    def frame_pose(self, ref_poses: ArrayLike) -> FloatArray:
        """Object-frame poses (N, 3) for reference-point poses (N, 3)."""
        p = np.atleast_2d(np.asarray(ref_poses, dtype=float)).copy()
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        rx, ry = self.ref
        p[:, 0] -= c * rx - s * ry
        p[:, 1] -= s * rx + c * ry
        return p

    def cell_of(self, pose: ArrayLike) -> tuple[int, int, int] | None:
        """(k, iy, ix): nearest heading bin and the cell of the reference point of an
        object-frame pose, or None outside the grid."""
        r = self.ref_pose(pose)
        c = self.frame.cell_of(r[:2])
        if c is None or not math.isfinite(r[2]):
            return None
        return self.bin_of(float(r[2])), c[0], c[1]

    def lattice_pose(self, k: int, iy: int, ix: int) -> FloatArray:
        """The object-frame pose of lattice state (k, iy, ix)."""
        x, y = self.frame.center(iy, ix)
        return self.frame_pose([x, y, self.heading_of(k)])[0]

    def is_free(self, pose: ArrayLike) -> bool:
        """Exact test of an object-frame pose: the grown footprint is clear."""
        return bool(self.checker.poses_free(self.ref_pose(pose)[None])[0])

    def clearance(self, pose: ArrayLike) -> tuple[float, str]:
        """Object polygon to the nearest obstacle or wall (m) at an object-frame pose, and which."""
        return self.checker.clearance(self.ref_pose(pose))

    def overlap(self, pose: ArrayLike) -> float:
        """Area (m²) of the object at an object-frame pose inside obstacles or beyond the walls."""
        return self.checker.overlap(self.ref_pose(pose))

    def pusher_room(self, pose: ArrayLike, direction: ArrayLike, cone: float) -> bool:
        """Whether a robot fits against the object at an object-frame pose where it can push it
        along ``direction`` (``FootprintChecker.pusher_room``)."""
        return self.checker.pusher_room(self.ref_pose(pose), direction, self.robot_radius, cone)

    def moves_free(self, k: int, iy: int, ix: int, moves: list[int]) -> list[bool]:
        """Exact, cached test of lattice moves from free state (k, iy, ix) to free neighbours.

        moves: 0-7 the translations of :data:`MOVES_8`, :data:`TURN_UP`, :data:`TURN_DOWN`.
        On a miss, every untested move between free states that are not both margin-free, from
        the states around this one (7 x 7 cells, 3 headings), is tested in one vectorised batch
        (a search that needs one of them soon needs its neighbours), and each result is cached
        for both ends of the move (the sweep is the same both ways).
        """
        k_bins, ny, nx = self.free.shape
        base = (k * ny + iy) * nx + ix
        got = [self._moves.get(base * 10 + mv) for mv in moves]
        if any(v is None for v in got):
            self._check_block(k, iy, ix)
            got = [self._moves.get(base * 10 + mv, False) for mv in moves]
        return got  # type: ignore[return-value]

    def _check_block(self, k: int, iy: int, ix: int) -> None:
        k_bins, ny, nx = self.free.shape
        bk, bxy = _BLOCK
        ks = sorted({(k + dk) % k_bins for dk in range(-bk, bk + 1)})
        y0, y1 = max(iy - bxy, 0), min(iy + bxy + 1, ny)
        x0, x1 = max(ix - bxy, 0), min(ix + bxy + 1, nx)
        a = np.argwhere(self.free[ks, y0:y1, x0:x1])
        a[:, 0] = np.asarray(ks)[a[:, 0]]
        a[:, 1] += y0
        a[:, 2] += x0
        moves = np.array([*((int(dx), int(dy), 0) for dx, dy in MOVES_8), (0, 0, 1), (0, 0, -1)])
        n_mv = 10 if k_bins > 1 else 8
        src = np.repeat(a, n_mv, axis=0)
        mv = np.tile(np.arange(n_mv), len(a))
        dst = src + moves[mv][:, [2, 1, 0]]
        dst[:, 0] %= k_bins
        inside = (dst[:, 1] >= 0) & (dst[:, 1] < ny) & (dst[:, 2] >= 0) & (dst[:, 2] < nx)
        src, mv, dst = src[inside], mv[inside], dst[inside]
        need = self.free[tuple(dst.T)] & ~(
            self.margin_free[tuple(src.T)] & self.margin_free[tuple(dst.T)]
        )
        fs = (src[:, 0] * ny + src[:, 1]) * nx + src[:, 2]
        fd = (dst[:, 0] * ny + dst[:, 1]) * nx + dst[:, 2]
        keys = fs * 10 + mv
        need &= np.array([key not in self._moves for key in keys.tolist()], dtype=bool)
        src, dst, mv, fs, fd = src[need], dst[need], mv[need], fs[need], fd[need]
        if len(src) == 0:
            return
        xs, ys = self.frame.centers()
        pose = np.stack([xs[src[:, 2]], ys[src[:, 1]], src[:, 0] * self.step], 1)
        ok = np.zeros(len(src), dtype=bool)
        tr = mv < 8
        if tr.any():
            steps = MOVES_8[mv[tr]] * self.frame.resolution
            ok[tr] = self.checker.translations_free(pose[tr], steps)
        if (~tr).any():
            turns = np.where(mv[~tr] == TURN_UP, self.step, -self.step)
            ok[~tr] = self.checker.rotations_free(pose[~tr], turns)
        back = np.where(mv < 8, (mv + 4) % 8, np.where(mv == TURN_UP, TURN_DOWN, TURN_UP))
        self._moves.update(zip((fs * 10 + mv).tolist(), ok.tolist(), strict=True))
        self._moves.update(zip((fd * 10 + back).tolist(), ok.tolist(), strict=True))


def build_object_cspace(
    bounds: ArrayLike,
    obstacles: list[ArrayLike],
    footprint_polygon: ArrayLike,
    robot_radius: float,
    resolution: float,
    heading_bins: int,
) -> ObjectCSpace:
    """Build the object's lattice C-space (see the module docstring).

    bounds: [[xmin, ymin], [xmax, ymax]] (m); obstacles: polygons (n, 2) in the world frame (m);
    footprint_polygon: the object polygon in its own frame (m); robot_radius: the largest robot
    radius (m), the ring is one robot diameter; resolution (m); heading_bins: K >= 1.
    Raises :class:`CSpaceError` (a ConfigError) naming the bad parameter.
    """
    frame = GridFrame.over(bounds, resolution)
    if not (isinstance(robot_radius, int | float) and 0 <= robot_radius < math.inf):
        raise CSpaceError("robot_radius", f"expected a finite number >= 0 m, got {robot_radius!r}")
    if isinstance(heading_bins, bool) or not isinstance(heading_bins, int | np.integer):
        raise CSpaceError("heading_bins", f"expected an integer >= 1, got {heading_bins!r}")
    if heading_bins < 1:
        raise CSpaceError("heading_bins", f"expected an integer >= 1, got {heading_bins!r}")
    k_bins = int(heading_bins)
    polys = [_polygon(o, f"obstacles[{i}]") for i, o in enumerate(obstacles)]
    poly = _polygon(footprint_polygon, "footprint")
    ref = reference_point(poly)
    poly_ref = poly - ref
    checker = FootprintChecker(bounds, polys, poly_ref, 2.0 * float(robot_radius))
    req = checker.req
    hd = resolution * math.sqrt(0.5)
    margin = max(hd, 2.0 * checker.rho * math.sin(math.pi / (2 * k_bins))) if k_bins > 1 else hd
    dist = clearance_raster(frame, checker.box, polys, req + 2.0 * hd + margin + 1.0)
    k0, m0 = footprint_kernels(poly_ref, resolution, k_bins, 0.0)
    khd, mhd = footprint_kernels(poly_ref, resolution, k_bins, hd + 1e-9)
    (sure,) = _correlate_any([dist < req - _TOL], k0, m0)
    maybe, near = _correlate_any(
        [dist < req + hd + 1e-9, dist < req + hd + margin + 1e-9], khd, mhd
    )
    uncertain = maybe & ~sure
    free = ~maybe
    idx = np.argwhere(uncertain)
    if len(idx):
        xs, ys = frame.centers()
        poses = np.stack([xs[idx[:, 2]], ys[idx[:, 1]], idx[:, 0] * (2.0 * math.pi / k_bins)], 1)
        free[uncertain] = checker.poses_free(poses)
    counts = {
        "states": int(free.size),
        "free": int(free.sum()),
        "exact_checked": int(len(idx)),
        "surely_colliding": int(sure.sum()),
    }
    return ObjectCSpace(
        frame=frame,
        heading_bins=k_bins,
        free=free,
        margin_free=~near,
        footprint=poly,
        ref=ref,
        robot_radius=float(robot_radius),
        checker=checker,
        counts=counts,
    )


# --------------------------------------------------------------------------- a robot disc


@dataclass(frozen=True, eq=False)
class RobotCSpace:
    """A robot disc's (x, y) C-space: ``occupied[iy, ix]`` and 8-connected component ``labels``."""

    frame: GridFrame
    occupied: BoolArray
    labels: NDArray[np.int32]
    radius: float

    def is_free(self, xy: ArrayLike) -> bool:
        """Whether the point (m) falls in a free cell."""
        c = self.frame.cell_of(xy)
        return c is not None and not bool(self.occupied[c])

    @staticmethod
    def from_occupancy(occupied: ArrayLike, frame: GridFrame, radius: float = 0.0) -> RobotCSpace:
        """Wrap a ready C-space occupancy (ny, nx) bool (e.g. a benchmark maze)."""
        occ = np.asarray(occupied, dtype=bool)
        if occ.shape != (frame.ny, frame.nx):
            raise CSpaceError("occupied", f"expected shape {(frame.ny, frame.nx)}, got {occ.shape}")
        labels, _ = ndimage.label(~occ, structure=np.ones((3, 3), dtype=bool))
        return RobotCSpace(frame, occ, labels.astype(np.int32), float(radius))


def build_robot_cspace(
    bounds: ArrayLike, obstacles: list[ArrayLike], radius: float, resolution: float
) -> RobotCSpace:
    """C-space of a robot disc of ``radius`` m: obstacles grown by the disc, conservatively.

    A cell is occupied when its centre lies closer than ``radius + resolution / sqrt(2)`` to an
    obstacle or a wall (exact distances): every point of a grid move between two free cell
    centres then keeps the disc off every obstacle.
    """
    frame = GridFrame.over(bounds, resolution)
    if not (isinstance(radius, int | float) and 0 <= radius < math.inf):
        raise CSpaceError("radius", f"expected a finite number >= 0 m, got {radius!r}")
    polys = [_polygon(o, f"obstacles[{i}]") for i, o in enumerate(obstacles)]
    b = _bounds(bounds)
    box = (float(b[0, 0]), float(b[0, 1]), float(b[1, 0]), float(b[1, 1]))
    need = radius + resolution * math.sqrt(0.5)
    dist = clearance_raster(frame, box, polys, need + 1.0)
    return RobotCSpace.from_occupancy(dist < need - _TOL, frame, radius)
