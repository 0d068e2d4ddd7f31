"""Run metrics from logged tracks: pure functions over arrays (the replay's arithmetic).

Tracks are ``(t (T,), xyz (T, 3))`` pairs in seconds and metres/radians; nothing here reads a
file or a clock (``controller.replay`` does the I/O).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller import geometry

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Track:
    """A time series of planar poses, sorted by time."""

    t: FloatArray  # (T,)
    pose: FloatArray  # (T, 3)

    @classmethod
    def from_rows(cls, rows: ArrayLike) -> Track:
        a = np.asarray(rows, dtype=float).reshape(-1, 4)
        a = a[np.argsort(a[:, 0], kind="stable")]
        return cls(a[:, 0], a[:, 1:4])

    def __len__(self) -> int:
        return len(self.t)

    def at(self, times: ArrayLike) -> FloatArray:
        """Poses linearly interpolated at ``times`` (clamped at the ends; angles unwrapped)."""
        times = np.asarray(times, dtype=float)
        th = np.unwrap(self.pose[:, 2])
        cols = [np.interp(times, self.t, self.pose[:, k]) for k in (0, 1)]
        cols.append(geometry.wrap_angle(np.interp(times, self.t, th)))
        return np.stack(cols, axis=-1)


def rate_hz(t: ArrayLike) -> float:
    """Mean message rate over the span of the stamps (0 for fewer than two)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2 or t[-1] <= t[0]:
        return 0.0
    return float((len(t) - 1) / (t[-1] - t[0]))


def path_length(xy: ArrayLike) -> float:
    """Length of the polyline through the points (m)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))) if len(xy) > 1 else 0.0


def tracking_error(estimate: Track, truth: Track) -> dict[str, float] | None:
    """Position error of an estimate against ground truth at the estimate's stamps (within the
    truth's span): RMSE, median, max (m) and heading RMSE (rad). None without overlap."""
    if len(estimate) == 0 or len(truth) < 2:
        return None
    inside = (estimate.t >= truth.t[0]) & (estimate.t <= truth.t[-1])
    if not np.any(inside):
        return None
    ref = truth.at(estimate.t[inside])
    est = estimate.pose[inside]
    d = np.linalg.norm(est[:, :2] - ref[:, :2], axis=1)
    dth = geometry.wrap_angle(est[:, 2] - ref[:, 2])
    return {
        "rmse_m": float(np.sqrt(np.mean(d**2))),
        "median_m": float(np.median(d)),
        "max_m": float(np.max(d)),
        "heading_rmse_rad": float(np.sqrt(np.mean(np.asarray(dth) ** 2))),
        "samples": int(inside.sum()),
    }


def common_grid(tracks: list[Track], dt: float | None = None) -> FloatArray:
    """Time stamps covered by every track: the first track's stamps inside the common span, or a
    regular grid of step ``dt``."""
    live = [tr for tr in tracks if len(tr) > 0]
    if not live:
        return np.zeros(0)
    lo = max(tr.t[0] for tr in live)
    hi = min(tr.t[-1] for tr in live)
    if hi < lo:
        return np.zeros(0)
    if dt is not None:
        return np.arange(lo, hi + 0.5 * dt, dt)
    t = live[0].t
    return t[(t >= lo) & (t <= hi)]


def min_clearance(tracks: list[Track], radii: ArrayLike) -> tuple[float, float] | None:
    """Smallest gap between robot discs over time, ``min_t min_ij |p_i − p_j| − r_i − r_j`` (m),
    and when it happened. None for fewer than two robots or no common time."""
    radii = np.asarray(radii, dtype=float)
    if len(tracks) < 2:
        return None
    grid = common_grid(tracks)
    if len(grid) == 0:
        return None
    gap = clearance_series(tracks, radii, grid)
    k = int(np.argmin(gap))
    return float(gap[k]), float(grid[k])


def clearance_series(tracks: list[Track], radii: ArrayLike, grid: ArrayLike) -> FloatArray:
    """The smallest robot-robot gap (m) at each time of ``grid``."""
    xy = np.stack([tr.at(grid)[:, :2] for tr in tracks], axis=1)  # (T, N, 2)
    return np.asarray(geometry.min_disc_gap(xy, radii), dtype=float).reshape(len(grid))


def obstacle_contacts(
    robots: list[Track],
    radii: ArrayLike,
    obstacles: list[ArrayLike],
    bounds: ArrayLike | None,
) -> list[int]:
    """Indices of the robots whose disc ever overlapped a static obstacle or crossed a wall."""
    out = []
    for i, (tr, r) in enumerate(zip(robots, np.asarray(radii, dtype=float), strict=True)):
        if len(tr) and geometry.discs_touch_static(tr.pose[:, :2], r, obstacles, bounds).any():
            out.append(i)
    return out


def object_penetration(
    robots: list[Track], radii: ArrayLike, obj: Track, polygon: ArrayLike
) -> tuple[float, float]:
    """Deepest overlap of a robot disc with the object (m, ≥ 0) and when it happened."""
    radii = np.asarray(radii, dtype=float)
    grid = common_grid([obj, *robots])
    deepest, when = 0.0, float(grid[0]) if len(grid) else 0.0
    if len(grid) == 0 or not robots:
        return 0.0, when
    opose = obj.at(grid)
    xy = np.stack([tr.at(grid)[:, :2] for tr in robots], axis=1)  # (T, N, 2)
    poly = np.asarray(polygon, dtype=float)
    for k in range(len(grid)):
        # robot centres in the object frame: one polygon, no re-transform of the shape
        local = geometry.inverse_transform(xy[k], opose[k])
        depth = radii - geometry.polygon_signed_distance(local, poly)
        m = float(np.max(depth))
        if m > deepest:
            deepest, when = m, float(grid[k])
    return deepest, when


def arrival_spread(contact_times: ArrayLike) -> float | None:
    """Time between the first and the last robot reaching contact (s)."""
    t = np.asarray(contact_times, dtype=float)
    return float(t.max() - t.min()) if len(t) else None


def hold_displacement(obj: Track, polygon: ArrayLike, t0: float, t1: float) -> float | None:
    """How far the object moved (m, its farthest vertex) between ``t0`` and ``t1`` from where it
    was at ``t0``; None when the track has no sample in that span."""
    if len(obj) == 0:
        return None
    inside = (obj.t >= t0) & (obj.t <= t1)
    if not np.any(inside):
        return None
    poly = np.asarray(polygon, dtype=float)
    start = geometry.transform(poly, obj.at(t0))
    moved = [
        float(np.max(np.linalg.norm(geometry.transform(poly, p) - start, axis=1)))
        for p in obj.pose[inside]
    ]
    return max(moved)


def object_clearance(
    obj: Track, polygon: ArrayLike, obstacles: list[ArrayLike], bounds: ArrayLike | None
) -> tuple[float, float] | None:
    """The object's smallest distance (m) to static obstacles and walls over the track
    (negative: it overlapped one), and when; None for an empty track or an empty room."""
    if len(obj) == 0 or (not obstacles and bounds is None):
        return None
    poly = np.asarray(polygon, dtype=float)
    d = track_clearance(poly, np.asarray(obj.pose, dtype=float), obstacles, bounds)
    k = int(np.argmin(d))
    return float(d[k]), float(obj.t[k])


def track_clearance(
    poly: np.ndarray, poses: np.ndarray, obstacles: list[ArrayLike], bounds: ArrayLike | None
) -> np.ndarray:
    """``geometry.polygon_clearance`` of the body-frame polygon at every pose (K, 3) at once
    (K,): the object's vertices in the world against each obstacle, and each obstacle's
    vertices in the object's frame against the body polygon (a rigid motion keeps distances)."""
    k, v = len(poses), len(poly)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (K, 2, 2)
    world = np.einsum("kij,vj->kvi", rot, poly) + poses[:, None, :2]  # (K, V, 2)
    best = np.full(k, np.inf)
    for o in obstacles:
        q = np.asarray(o, dtype=float)
        a = geometry.polygon_signed_distance(world.reshape(-1, 2), q).reshape(k, v).min(1)
        body = np.einsum("kji,kqj->kqi", rot, q[None] - poses[:, None, :2])  # (K, Q, 2)
        b = geometry.polygon_signed_distance(body.reshape(-1, 2), poly).reshape(k, -1).min(1)
        best = np.minimum(best, np.minimum(a, b))
    if bounds is not None:
        (x0, y0), (x1, y1) = np.asarray(bounds, dtype=float)
        x, y = world[..., 0], world[..., 1]
        walls = np.minimum(np.minimum(x - x0, x1 - x), np.minimum(y - y0, y1 - y)).min(1)
        best = np.minimum(best, walls)
    return best


def phase_index(times: ArrayLike, starts: ArrayLike) -> NDArray[np.int_]:
    """For each time, the index of the phase it falls in (phases begin at ``starts``, sorted;
    -1 before the first)."""
    return np.searchsorted(np.asarray(starts, float), np.asarray(times, float), side="right") - 1


def lateral_deviation(points: ArrayLike, path: ArrayLike) -> FloatArray:
    """Distance (m) of each point (T, 2) from a polyline (M, 2): how far the object is off its
    route."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(p) == 0:
        return np.full(len(pts), np.nan)
    if len(p) == 1:
        return np.linalg.norm(pts - p[0], axis=1)
    d, _ = geometry.point_segment_distance(pts, p[:-1], p[1:])
    return d.min(axis=1)
