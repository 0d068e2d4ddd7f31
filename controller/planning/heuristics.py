"""Potential-field heuristics for the route search (Yamashita et al. §3).

Each function returns a table of distances to the goal in metres over an (ny, nx) grid (``inf``
where the goal cannot be reached); the route planner divides by the formation's speed, so the
heuristics are "normalized by the velocity" as in the paper, and adds a rotation term.

Admissibility (for the planner's moves: 8-connected steps of ``res`` or ``res * sqrt(2)`` metres
between free cells of a heading layer, and heading steps in place):

- **(A) Euclid** -- straight-line distance between cell centres. Admissible and consistent
  (triangle inequality), and the weakest: it ignores obstacles.
- **(B) Wavefront** -- the 8-connected grid distance to the goal through the *projected* free
  space (cells free at one heading at least), computed by Dijkstra in ``scipy.sparse.csgraph``.
  Every object path projects onto a walk through that space, so the value is a lower bound:
  admissible and consistent, and exact in the 2-D robot C-space.
- **(C) Skeleton wavefront** (Barraquand & Latombe) -- the wavefront run *along the skeleton*
  (medial axis) of the projected free space from the goal, plus each cell's grid distance to its
  nearest skeleton cell. It steers the search down the middle of corridors, away from the cells
  near obstacles. It is **not admissible**: the detour to and along the skeleton overestimates,
  so with ``w_h = 1`` the path may cost a little more than the optimum. It is never below (B).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse import csgraph

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

HEURISTICS = ("euclid", "wavefront", "skeleton")
_NO_PRED = -9999


def grid_graph(free: BoolArray) -> sparse.csr_matrix:
    """8-connected graph over the free cells of an (ny, nx) mask, edge weights in cells (1, sqrt 2).

    Node ``iy * nx + ix``; diagonal steps may pass between two occupied orthogonal cells, as the
    planner's moves do (the C-space margins make that safe).
    """
    ny, nx = free.shape
    idx = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, wts = [], [], []
    for dy, dx, w in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, math.sqrt(2.0)), (1, -1, math.sqrt(2.0))):
        a = free[max(0, -dy) : ny - max(0, dy), max(0, -dx) : nx - max(0, dx)]
        b = free[max(0, dy) : ny + min(0, dy), max(0, dx) : nx + min(0, dx)]
        ia = idx[max(0, -dy) : ny - max(0, dy), max(0, -dx) : nx - max(0, dx)]
        ib = idx[max(0, dy) : ny + min(0, dy), max(0, dx) : nx + min(0, dx)]
        ok = a & b
        u, v = ia[ok], ib[ok]
        rows += [u, v]
        cols += [v, u]
        wts += [np.full(u.size, w), np.full(u.size, w)]
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    w = np.concatenate(wts)
    return sparse.csr_matrix((w, (r, c)), shape=(ny * nx, ny * nx))


def euclid(free: BoolArray, goal: tuple[int, int], resolution: float) -> FloatArray:
    """(A) Straight-line distance (m) from each cell centre to the goal cell centre. Admissible."""
    ny, nx = free.shape
    gy, gx = goal
    yy, xx = np.mgrid[0:ny, 0:nx]
    return np.hypot(yy - gy, xx - gx) * resolution


def wavefront(
    free: BoolArray,
    goal: tuple[int, int],
    resolution: float,
    graph: sparse.csr_matrix | None = None,
) -> FloatArray:
    """(B) 8-connected grid distance (m) to the goal through free cells (inf if cut off)."""
    ny, nx = free.shape
    g = graph if graph is not None else grid_graph(free)
    d = csgraph.dijkstra(g, directed=False, indices=goal[0] * nx + goal[1])
    out = d.reshape(ny, nx) * resolution
    out[~free] = np.inf
    return out


def _zhang_suen_luts() -> tuple[BoolArray, BoolArray]:
    codes = np.arange(256)
    b = (codes[:, None] >> np.arange(8)) & 1  # P2..P9 = N, NE, E, SE, S, SW, W, NW
    count = b.sum(axis=1)
    trans = ((b == 0) & (np.roll(b, -1, axis=1) == 1)).sum(axis=1)
    base = (count >= 2) & (count <= 6) & (trans == 1)
    p2, p4, p6, p8 = b[:, 0], b[:, 2], b[:, 4], b[:, 6]
    first = base & (p2 * p4 * p6 == 0) & (p4 * p6 * p8 == 0)
    second = base & (p2 * p4 * p8 == 0) & (p2 * p6 * p8 == 0)
    return first, second


def zhang_suen_thin(mask: BoolArray) -> BoolArray:
    """Skeleton of a binary image by Zhang-Suen thinning, vectorized with a 256-entry lookup table.

    Each sub-iteration computes every pixel's 8-neighbour code with array slices and deletes the
    removable border pixels at once; it stops when nothing changes. Thinning keeps each connected
    component connected (8-connectivity).
    """
    first, second = _zhang_suen_luts()
    img = np.pad(np.asarray(mask, dtype=bool), 1).astype(np.uint8)
    while True:
        changed = False
        for lut in (first, second):
            c = img[1:-1, 1:-1]
            code = (
                img[:-2, 1:-1]
                | (img[:-2, 2:] << 1)
                | (img[1:-1, 2:] << 2)
                | (img[2:, 2:] << 3)
                | (img[2:, 1:-1] << 4)
                | (img[2:, :-2] << 5)
                | (img[1:-1, :-2] << 6)
                | (img[:-2, :-2] << 7)
            )
            remove = (c == 1) & lut[code]
            if remove.any():
                c[remove] = 0
                changed = True
        if not changed:
            return img[1:-1, 1:-1].astype(bool)


def skeleton_wavefront(
    free: BoolArray,
    goal: tuple[int, int],
    resolution: float,
    graph: sparse.csr_matrix | None = None,
    skeleton: BoolArray | None = None,
) -> FloatArray:
    """(C) Skeleton wavefront (m): along the skeleton from the goal, plus the way to the skeleton.

    The goal is joined to the skeleton by its shortest free path to the nearest skeleton cell;
    that path counts as skeleton. For a cell c with nearest skeleton cell s(c) (grid distance
    d(c)), the value is ``W(s(c)) + d(c)`` where W is the wavefront from the goal restricted to
    skeleton cells. Cells whose skeleton piece is cut off from the goal's fall back to (B).
    Not admissible (see the module docstring); never below (B).
    """
    ny, nx = free.shape
    g = graph if graph is not None else grid_graph(free)
    wave = wavefront(free, goal, resolution, g)
    skel = (zhang_suen_thin(free) if skeleton is None else skeleton) & free
    goal_i = goal[0] * nx + goal[1]
    s_idx = np.flatnonzero(skel.ravel())
    if s_idx.size == 0 or not free[goal]:
        return wave
    _, pred, _ = csgraph.dijkstra(
        g, directed=False, indices=s_idx, min_only=True, return_predecessors=True
    )
    path = [goal_i]
    while pred[path[-1]] != _NO_PRED:
        path.append(int(pred[path[-1]]))
    on = skel.ravel().copy()
    on[path] = True
    t_idx = np.flatnonzero(on)
    sub = g[t_idx][:, t_idx]
    start = int(np.searchsorted(t_idx, goal_i))
    w_sub = csgraph.dijkstra(sub, directed=False, indices=start)
    w_full = np.full(ny * nx, np.inf)
    w_full[t_idx] = w_sub
    d2, _, src = csgraph.dijkstra(
        g, directed=False, indices=t_idx, min_only=True, return_predecessors=True
    )
    out = np.full(ny * nx, np.inf)
    ok = src >= 0
    out[ok] = d2[ok] + w_full[src[ok]]
    out = out.reshape(ny, nx) * resolution
    fallback = ~np.isfinite(out)
    out[fallback] = wave[fallback]
    out[goal] = 0.0
    return np.maximum(out, wave)


def heuristic_table(
    kind: str, free: BoolArray, goal: tuple[int, int], resolution: float
) -> FloatArray:
    """The named heuristic's distance table (m) over the (ny, nx) grid (see :data:`HEURISTICS`)."""
    if kind == "euclid":
        return euclid(free, goal, resolution)
    if kind == "wavefront":
        return wavefront(free, goal, resolution)
    if kind == "skeleton":
        return skeleton_wavefront(free, goal, resolution)
    raise ValueError(f"heuristic: expected one of {', '.join(HEURISTICS)}, got {kind!r}")


def _ray_orders(shape: tuple[int, int], moves: NDArray[np.int_]) -> list[tuple[NDArray, NDArray]]:
    """Per move direction: the cells ordered along the lines of that direction, and line starts."""
    ny, nx = shape
    iy, ix = np.mgrid[0:ny, 0:nx]
    iy, ix = iy.ravel(), ix.ravel()
    out = []
    for dx, dy in moves:
        if dy == 0:
            line = iy
        elif dx == 0:
            line = ix
        elif dx == dy:
            line = iy - ix
        else:
            line = iy + ix
        t = dx * ix + dy * iy
        order = np.lexsort((t, line))
        start = np.r_[True, line[order][1:] != line[order][:-1]]
        out.append((order, start))
    return out


def turn_bounds(
    free: BoolArray, goal: tuple[int, int], moves: NDArray[np.int_]
) -> tuple[FloatArray, FloatArray]:
    """Fewest changes of travel direction to reach the goal (link distance), a manipulation bound.

    ``moves`` are the (dx, dy) cell steps (e.g. ``cspace.MOVES_8``). Returns ``T`` (len(moves),
    ny, nx): the fewest direction changes from a cell when the last move was ``moves[d]``
    (continuing straight is free), and ``V`` (ny, nx): the same with the first direction free;
    inf where the goal cannot be reached. Any walk through the free cells changes direction at
    least that often, so ``manipulation_cost * T`` is an admissible addition to a distance
    heuristic when each change of direction is charged. Computed by iterating
    ``T_d(c) = min over the ray from c along d of (0 at the goal, else 1 + V)`` to a fixed point;
    each ray minimum is one segmented reverse cumulative minimum along the lines of direction d.
    """
    ny, nx = free.shape
    n = ny * nx
    big_val = float(n + 2)  # stands for inf (more turns than cells is impossible)
    seg_scale = 4.0 * big_val
    fr = free.ravel()
    is_goal = np.zeros(n, dtype=bool)
    is_goal[goal[0] * nx + goal[1]] = True
    orders = []
    for order, start in _ray_orders(free.shape, moves):
        f_o = fr[order]
        change = np.r_[True, f_o[1:] != f_o[:-1]]
        seg = np.cumsum(start | change).astype(float)
        orders.append((order, seg * seg_scale, f_o))
    v = np.full(n, big_val)
    t_all = np.full((len(moves), n), big_val)
    for _ in range(n):
        q = np.where(is_goal, 0.0, np.minimum(v + 1.0, big_val))
        q[~fr] = big_val
        for d, (order, off, f_o) in enumerate(orders):
            w = q[order] + off
            r = np.minimum.accumulate(w[::-1])[::-1] - off
            r[~f_o] = big_val
            t_all[d, order] = r
        v_new = t_all.min(axis=0)
        if np.array_equal(v_new, v):
            break
        v = v_new
    t_all[t_all >= big_val] = np.inf
    v = t_all.min(axis=0)
    return t_all.reshape(len(moves), ny, nx), v.reshape(ny, nx)
