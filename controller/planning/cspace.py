"""Grid configuration spaces: the carried object's (x, y, theta) and a robot disc's (x, y).

Pure numpy/scipy, no I/O. The world inside ``bounds`` is cut into square cells of side
``resolution`` (m); cell ``(iy, ix)`` has its centre at
``(x0 + (ix + 0.5) res, y0 + (iy + 0.5) res)``.
Everything outside the bounds is an obstacle (the walls).

How the object's C-space is made (Yamashita et al. §3, with a uniform grid in place of the octree):

1. The obstacles are rasterized **conservatively**: a cell is occupied when its square touches an
   obstacle polygon (tested as "centre within half a cell diagonal of the polygon").
2. The carried footprint is the object polygon grown by one robot diameter (the ring of robots
   around it). For each heading bin it is rasterized into a kernel of cell offsets, again
   conservatively, as the union over the whole heading bin, and grown by half a cell diagonal so
   that the straight move between two adjacent free cells (and the rotation between two adjacent
   free heading bins) is collision-free too, not only the cell centres.
3. The C-space obstacle of each heading is the obstacle raster correlated with that kernel
   (one batched FFT convolution over all headings): ``occupied[k, c]`` is true when some kernel
   cell placed at ``c`` lands on an occupied cell. No polygon is ever tested per node.

The result is conservative by construction: a pose at the centre of a free cell, and every pose
on a grid move between free cells, keeps the grown footprint off every obstacle. The price is up
to about one cell of extra clearance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, signal

from controller import geometry

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: 8-connected moves as (dx, dy) in cells: E, NE, N, NW, W, SW, S, SE (counter-clockwise from +x).
MOVES_8 = np.array(
    [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)], dtype=int
)


class CSpaceError(ValueError):
    """Bad C-space input (bounds, resolution, polygon); the message names the culprit."""


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
        b = np.asarray(bounds, dtype=float).reshape(2, 2)
        if not (resolution > 0 and math.isfinite(resolution)):
            raise CSpaceError(
                f"resolution: expected a positive number of metres, got {resolution!r}"
            )
        (x0, y0), (x1, y1) = b
        if not (x1 > x0 and y1 > y0):
            raise CSpaceError(
                f"bounds: expected [[xmin, ymin], [xmax, ymax]] with max > min, got {b}"
            )
        nx = int(math.ceil((x1 - x0) / resolution - 1e-9))
        ny = int(math.ceil((y1 - y0) / resolution - 1e-9))
        return GridFrame(float(x0), float(y0), float(resolution), nx, ny)

    def cell_of(self, xy: ArrayLike) -> tuple[int, int] | None:
        """(iy, ix) of the cell holding the point (m), or None outside the grid."""
        x, y = (float(v) for v in np.asarray(xy, dtype=float)[:2])
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


def rasterize_obstacles(frame: GridFrame, obstacles: list[ArrayLike]) -> BoolArray:
    """Conservative occupancy (ny, nx): a cell is occupied when its square may touch a polygon.

    A cell counts as touched when its centre lies within half a cell diagonal of the polygon
    (inside it, or closer than ``resolution / sqrt(2)`` to its boundary), a superset of the cells
    the polygon really overlaps.
    """
    occ = np.zeros((frame.ny, frame.nx), dtype=bool)
    r = frame.resolution
    half_diag = r * math.sqrt(0.5) + 1e-9
    for i, poly in enumerate(obstacles):
        p = np.asarray(poly, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
            raise CSpaceError(f"obstacles[{i}]: expected an (n>=3, 2) polygon, got shape {p.shape}")
        lo = np.floor((p.min(axis=0) - [frame.x0, frame.y0]) / r).astype(int) - 1
        hi = np.ceil((p.max(axis=0) - [frame.x0, frame.y0]) / r).astype(int) + 1
        ix0, iy0 = max(lo[0], 0), max(lo[1], 0)
        ix1, iy1 = min(hi[0], frame.nx), min(hi[1], frame.ny)
        if ix0 >= ix1 or iy0 >= iy1:
            continue
        xs = frame.x0 + (np.arange(ix0, ix1) + 0.5) * r
        ys = frame.y0 + (np.arange(iy0, iy1) + 0.5) * r
        gx, gy = np.meshgrid(xs, ys)
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        hit = geometry.polygon_signed_distance(pts, p) < half_diag
        occ[iy0:iy1, ix0:ix1] |= hit.reshape(gy.shape)
    return occ


def footprint_kernels(
    polygon: ArrayLike, grow: float, resolution: float, heading_bins: int
) -> tuple[BoolArray, int]:
    """Rasterized footprints, one per heading bin: (K, 2m+1, 2m+1) bool kernels and the half size m.

    ``kernel[k, m + dy, m + dx]`` is true when the polygon (object frame, m) grown by ``grow`` m,
    turned by any angle within heading bin k (centre ``k * 2 pi / K``, width ``2 pi / K``), may
    touch the cell at offset (dx, dy) cells, with half a cell diagonal more for the sweep of a
    grid move.
    """
    poly = geometry.ensure_ccw(np.asarray(polygon, dtype=float))
    k_bins = int(heading_bins)
    if k_bins < 1:
        raise CSpaceError(f"heading_bins: expected >= 1, got {heading_bins!r}")
    rho = float(np.max(np.linalg.norm(poly, axis=1)))
    width = 2.0 * math.pi / k_bins
    half_diag = resolution * math.sqrt(0.5)
    if k_bins == 1:
        sub = np.zeros(1)
        rot_margin = 0.0
    else:
        n_sub = int(math.ceil(rho * width / resolution)) + 1
        sub = np.linspace(-width / 2, width / 2, n_sub)
        rot_margin = rho * (width / (n_sub - 1)) / 2.0
    reach = grow + 2.0 * half_diag + rot_margin
    m = int(math.ceil((rho + reach) / resolution)) + 1
    f = np.arange(-m, m + 1) * resolution
    gx, gy = np.meshgrid(f, f)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    kernels = np.zeros((k_bins, 2 * m + 1, 2 * m + 1), dtype=bool)
    for k in range(k_bins):
        best = np.full(len(pts), np.inf)
        for a in k * width + sub:
            q = geometry.transform(poly, (0.0, 0.0, a))
            best = np.minimum(best, geometry.polygon_signed_distance(pts, q))
        kernels[k] = (best < reach + 1e-9).reshape(gx.shape)
    return kernels, m


def _label_with_wrap(free: BoolArray) -> NDArray[np.int32]:
    """Connected components of the (K, ny, nx) free cells under the planner's moves.

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


@dataclass(frozen=True, eq=False)
class ObjectCSpace:
    """The carried object's (x, y, theta) C-space: build once with :func:`build_object_cspace`.

    ``occupied[k, iy, ix]``: the grown footprint at the centre of cell (iy, ix) with heading
    ``k * 2 pi / K`` (rad) may touch an obstacle or leave the bounds. ``labels`` are the connected
    components of the free cells under the planner's moves (0 = occupied).
    """

    frame: GridFrame
    heading_bins: int
    occupied: BoolArray
    obstacles: BoolArray
    labels: NDArray[np.int32]
    footprint: FloatArray
    robot_radius: float

    @property
    def free(self) -> BoolArray:
        """Free cells (K, ny, nx)."""
        return ~self.occupied

    def heading_of(self, k: int) -> float:
        """Heading (rad, in [-pi, pi)) of bin k."""
        return float(geometry.wrap_angle(k * 2.0 * math.pi / self.heading_bins))

    def bin_of(self, theta: float) -> int:
        """Nearest heading bin of an angle (rad)."""
        return int(round(float(theta) / (2.0 * math.pi / self.heading_bins))) % self.heading_bins

    def cell_of(self, pose: ArrayLike) -> tuple[int, int, int] | None:
        """(k, iy, ix) of a pose (x, y, theta), or None outside the bounds."""
        p = np.asarray(pose, dtype=float)
        c = self.frame.cell_of(p[:2])
        if c is None:
            return None
        return self.bin_of(float(p[2])), c[0], c[1]

    def is_free(self, pose: ArrayLike) -> bool:
        """Whether the pose (x, y, theta) falls in a free C-space cell."""
        c = self.cell_of(pose)
        return c is not None and not bool(self.occupied[c])


def build_object_cspace(
    bounds: ArrayLike,
    obstacles: list[ArrayLike],
    footprint_polygon: ArrayLike,
    robot_radius: float,
    resolution: float,
    heading_bins: int,
) -> ObjectCSpace:
    """Build the object's C-space (see the module docstring).

    bounds: [[xmin, ymin], [xmax, ymax]] (m); obstacles: polygons (n, 2) in the world frame (m);
    footprint_polygon: the object polygon in its own frame (m); robot_radius: the largest robot
    radius (m), the footprint is grown by one robot diameter; resolution (m); heading_bins: K.
    """
    frame = GridFrame.over(bounds, resolution)
    if not robot_radius >= 0:
        raise CSpaceError(f"robot_radius: expected >= 0 m, got {robot_radius!r}")
    occ = rasterize_obstacles(frame, obstacles)
    kernels, m = footprint_kernels(footprint_polygon, 2.0 * robot_radius, resolution, heading_bins)
    padded = np.pad(occ.astype(np.float32), m, mode="constant", constant_values=1.0)
    # correlation with the kernel = convolution with the kernel flipped in both axes
    flipped = kernels[:, ::-1, ::-1].astype(np.float32)
    conv = signal.fftconvolve(padded[None], flipped, mode="valid", axes=(1, 2))
    occupied = conv > 0.5
    labels = _label_with_wrap(~occupied)
    return ObjectCSpace(
        frame=frame,
        heading_bins=int(heading_bins),
        occupied=occupied,
        obstacles=occ,
        labels=labels,
        footprint=geometry.ensure_ccw(np.asarray(footprint_polygon, dtype=float)),
        robot_radius=float(robot_radius),
    )


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
            raise CSpaceError(f"occupied: expected shape {(frame.ny, frame.nx)}, got {occ.shape}")
        labels, _ = ndimage.label(~occ, structure=np.ones((3, 3), dtype=bool))
        return RobotCSpace(frame, occ, labels.astype(np.int32), float(radius))


def build_robot_cspace(
    bounds: ArrayLike, obstacles: list[ArrayLike], radius: float, resolution: float
) -> RobotCSpace:
    """C-space of a robot disc of ``radius`` m: obstacles grown by the disc, conservatively.

    A cell is occupied when the distance from its centre to the nearest occupied obstacle cell's
    centre is below ``radius + resolution * sqrt(2)`` (half a diagonal for the conservative
    obstacle raster, half a diagonal for the sweep of a grid move); walls count as obstacles.
    """
    frame = GridFrame.over(bounds, resolution)
    if not radius >= 0:
        raise CSpaceError(f"radius: expected >= 0 m, got {radius!r}")
    occ = rasterize_obstacles(frame, obstacles)
    padded = np.pad(occ, 1, mode="constant", constant_values=True)
    dist = ndimage.distance_transform_edt(~padded)[1:-1, 1:-1] * resolution
    occupied = dist < radius + resolution * math.sqrt(2.0) - 1e-9
    occupied |= occ
    return RobotCSpace.from_occupancy(occupied, frame, radius)
