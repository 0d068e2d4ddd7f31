"""Heuristics for the route searches (Yamashita et al. §3) and the lattice cost-to-go.

The paper's potentials (A)-(C) are tables of distances to the goal in metres over an (ny, nx)
grid (``inf`` where the goal cannot be reached); the route planner divides them by the
formation's speed, so they are "normalized by the velocity" as in the paper, and adds a rotation
and a manipulation bound. (D) :func:`lattice_cost_to_go` is ours: the exact cost (s) to the goal
over the whole (x, y, theta) lattice, computed once per goal, the default.

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
- **(D) Cost-to-go** -- the cheapest cost (s) from every lattice state (x, y, theta) to the goal
  over the lattice's moves (translations at ``step_cost`` per cell, turns at ``turn_cost`` per
  heading bin), by a vectorised Dijkstra (:func:`lattice_cost_to_go`). With every move between
  free states counted as possible it is a lower bound of the true cost-to-go: admissible and
  consistent, and exact but for the manipulation cost and for moves found blocked by the exact
  sweep test. It is also what a re-plan from a new start reuses.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse import csgraph

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: The heuristics that are tables over the (x, y) grid (the paper's potentials).
POTENTIALS = ("euclid", "wavefront", "skeleton")
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


def euclid(free: BoolArray, goal: tuple[float, float], resolution: float) -> FloatArray:
    """(A) Straight-line distance (m) from each cell centre to the goal, given as (iy, ix) in
    cell units (a cell's index for its centre; fractional for an exact point). Admissible."""
    ny, nx = free.shape
    gy, gx = goal
    yy, xx = np.mgrid[0:ny, 0:nx]
    return np.hypot(yy - gy, xx - gx) * resolution


def wavefront(
    free: BoolArray,
    goal: tuple[int, int],
    resolution: float,
    graph: sparse.csr_matrix | None = None,
    seeds: tuple[NDArray[np.int_], FloatArray] | None = None,
) -> FloatArray:
    """(B) 8-connected grid distance (m) to the goal through free cells (inf if cut off).

    ``seeds`` (cells (m, 2) as (iy, ix), distances (m,) m) replaces the goal cell by several
    goal cells each with a distance still to go (the final step to an exact goal point).
    """
    ny, nx = free.shape
    g = graph if graph is not None else grid_graph(free)
    if seeds is None:
        d = csgraph.dijkstra(g, directed=False, indices=goal[0] * nx + goal[1])
    else:
        cells, dist = seeds
        n = ny * nx
        src = np.asarray(cells, dtype=int)
        w = np.asarray(dist, dtype=float) / resolution + 1e-12  # explicit zeros would vanish
        extra = sparse.csr_matrix(
            (w, (np.full(len(w), n), src[:, 0] * nx + src[:, 1])), shape=(n + 1, n + 1)
        )
        full = sparse.bmat([[g, None], [None, sparse.csr_matrix((1, 1))]], format="csr")
        d = csgraph.dijkstra(full + extra, directed=True, indices=n)[:n]
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
    """The named potential's distance table (m) over the (ny, nx) grid (see :data:`POTENTIALS`)."""
    if kind == "euclid":
        return euclid(free, goal, resolution)
    if kind == "wavefront":
        return wavefront(free, goal, resolution)
    if kind == "skeleton":
        return skeleton_wavefront(free, goal, resolution)
    raise ValueError(f"heuristic: expected one of {', '.join(POTENTIALS)}, got {kind!r}")


def octile(shape: tuple[int, int], goal: tuple[int, int], resolution: float) -> FloatArray:
    """Octile distance (m) from each cell of an (ny, nx) grid to the goal cell: the exact cost of
    8-connected moves with no obstacle (admissible and consistent for them)."""
    ny, nx = shape
    dy = np.abs(np.arange(ny) - goal[0])[:, None]
    dx = np.abs(np.arange(nx) - goal[1])[None, :]
    lo, hi = np.minimum(dx, dy), np.maximum(dx, dy)
    return (hi + (math.sqrt(2.0) - 1.0) * lo) * resolution


def landmark_distances(free: BoolArray, count: int, resolution: float) -> FloatArray:
    """Grid distances (m) from ``count`` landmarks to every cell of an (ny, nx) free mask,
    (count, ny, nx), inf where a landmark cannot reach. Landmarks by farthest-point selection:
    the first free cell, then each time the free cell farthest from those chosen (preferring
    cells no landmark reaches yet), so they sit at the far ends of the free space.
    """
    ny, nx = free.shape
    if count <= 0 or not free.any():
        return np.zeros((0, ny, nx))
    g = grid_graph(free)
    chosen: list[int] = [int(np.flatnonzero(free.ravel())[0])]
    rows = []
    nearest = np.full(ny * nx, np.inf)
    for _ in range(count):
        d = csgraph.dijkstra(g, directed=False, indices=chosen[-1]) * resolution
        rows.append(d)
        nearest = np.minimum(nearest, d)
        score = np.where(np.isfinite(nearest), nearest, 1e300)
        score[~free.ravel()] = -1.0
        nxt = int(np.argmax(score))
        if score[nxt] <= 0 or len(rows) == count:
            break
        chosen.append(nxt)
    return np.array(rows).reshape(len(rows), ny, nx)


def landmark_bound(
    landmarks: FloatArray, goal: tuple[int, int], base: FloatArray | None = None
) -> FloatArray:
    """ALT lower bound (m) of the grid distance to ``goal`` from every cell: the largest
    ``|d(L, goal) - d(L, n)|`` over the landmarks that reach both (the triangle inequality),
    and at least ``base`` (e.g. the octile distance). Admissible and consistent."""
    out = np.zeros(landmarks.shape[1:]) if base is None else np.array(base, dtype=float)
    for d in landmarks:
        dg = d[goal]
        if np.isfinite(dg):
            gap = np.abs(dg - d)
            np.maximum(out, np.where(np.isfinite(gap), gap, 0.0), out=out)
    return out


def _seed_table(shape: tuple[int, int, int], seeds: tuple[NDArray[np.int_], FloatArray]):
    """The seeds as a (K, ny, nx) table of costs (inf elsewhere; the cheapest per state)."""
    cells, cost = seeds
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    out = np.full(shape, np.inf)
    np.minimum.at(out, (cells[:, 0], cells[:, 1], cells[:, 2]), np.asarray(cost, dtype=float))
    return out


def _mode_free_cost_to_go(
    free: BoolArray, join: FloatArray, step_cost: float, turn_cost: float
) -> FloatArray:
    """Dijkstra on the lattice with every move between free states, no manipulation cost.

    Vectorised by buckets of width ``min(step_cost, turn_cost)`` (delta-stepping with delta at
    most the lightest move: every state in the lightest bucket is final, so each bucket is
    settled at once with one array operation per move).
    """
    k_bins, ny, nx = free.shape
    w, h = nx + 2, ny + 2
    layer = w * h
    fp = np.zeros((k_bins, h, w), dtype=bool)
    fp[:, 1:-1, 1:-1] = free
    fr = fp.ravel()
    jp = np.full((k_bins, h, w), np.inf)
    jp[:, 1:-1, 1:-1] = np.where(free, join, np.inf)
    dist = jp.ravel().copy()
    pend_i = np.flatnonzero(np.isfinite(dist))
    pend_d = dist[pend_i]
    moves = [(int(dy * w + dx), step_cost * math.hypot(dx, dy)) for dx, dy in _MOVES8]
    delta = step_cost if k_bins == 1 else min(step_cost, turn_cost)
    while pend_i.size:
        hi = pend_d.min() + delta
        sel = pend_d < hi
        a, da = pend_i[sel], pend_d[sel]
        pend_i, pend_d = pend_i[~sel], pend_d[~sel]
        live = dist[a] == da
        a, da = a[live], da[live]
        new_i, new_d = [pend_i], [pend_d]
        targets = [(a + off, da + c) for off, c in moves]
        if k_bins > 1:
            k = a // layer
            up = np.where(k == k_bins - 1, a - (k_bins - 1) * layer, a + layer)
            dn = np.where(k == 0, a + (k_bins - 1) * layer, a - layer)
            targets += [(up, da + turn_cost), (dn, da + turn_cost)]
        for b, c in targets:
            better = fr[b] & (c < dist[b])
            b, c = b[better], c[better]
            dist[b] = c
            new_i.append(b)
            new_d.append(c)
        pend_i, pend_d = np.concatenate(new_i), np.concatenate(new_d)
    return dist.reshape(k_bins, h, w)[:, 1:-1, 1:-1]


def _sweep(value, penalty, sign: int, costs, acc, out) -> None:
    """Straight runs along axis 0 of (n, K, m) arrays, min into ``acc`` (``out`` is scratch).

    For each (lateral step, cost w) in ``costs``, the run direction d is ``sign`` along axis 0
    and the lateral step along axis 2; ``R(c) = w + min(value(c + d), R(c + d)) + penalty(c)``
    (``penalty`` is inf at states that are not free, so runs stop there): the cheapest run of
    j >= 1 moves from c plus the value where it ends. One vectorised (K, m) step per index.
    """
    n, _, m = value.shape
    first = n - 1 if sign > 0 else 0
    for lateral, w in costs:
        out[first] = np.inf
        if lateral == 0:
            dst, src = slice(None), slice(None)
        elif lateral > 0:
            dst, src = slice(0, m - 1), slice(1, m)
            out[:, :, m - 1] = np.inf
        else:
            dst, src = slice(1, m), slice(0, m - 1)
            out[:, :, 0] = np.inf
        for i in range(n - 2, -1, -1) if sign > 0 else range(1, n):
            r = out[i, :, dst]
            np.minimum(value[i + sign, :, src], out[i + sign, :, src], out=r)
            r += w
            r += penalty[i, :, dst]
            a = acc[i, :, dst]
            np.minimum(a, r, out=a)


class _Seeds:
    """Goal states in the sweeps' layouts, and what ending a run on one costs for each kind of
    run: the seed's cost, plus the manipulation cost unless the run's kind is the one the way
    to the goal begins with (``first``: 0-7 a translation direction, 8 turning, -1 any)."""

    def __init__(self, cells, cost, first, manip: float, shape: tuple[int, int, int]):
        k_bins, ny, nx = shape
        k, iy, ix = cells[:, 0], cells[:, 1], cells[:, 2]
        self.at_x = (ix * k_bins + k) * ny + iy  # flat index in (nx, K, ny)
        self.at_y = (iy * k_bins + k) * nx + ix  # flat index in (ny, K, nx)
        self.cost = np.asarray(cost, dtype=np.float32)
        self.first = np.asarray(first)
        self.manip = np.float32(manip)

    def patch(self, flat, at, cost_here, kind: int | None) -> None:
        """Set ``min(seed cost (+ charge), manip + cost)`` at the seeds of a flat array."""
        flat[at] = cost_here + self.manip
        if kind is None:
            charge = np.zeros(len(self.cost), dtype=np.float32)
        else:
            charge = np.where((self.first == kind) | (self.first < 0), 0, self.manip)
        np.minimum.at(flat, at, self.cost + charge.astype(np.float32))


class _RunCosts:
    """Cheapest straight runs on a (K, ny, nx) lattice, computed in the layouts the sweeps want:
    arrays are held as (nx, K, ny) (x runs and diagonals along axis 0, turns along axis 1) and
    copied to (ny, K, nx) for the y runs. float32; workspace allocated once for every round."""

    def __init__(self, free: BoolArray, step_cost: float, turn_cost: float, seeds: _Seeds):
        self.k_bins = free.shape[0]
        pen = np.where(free, np.float32(0.0), np.float32(np.inf))
        self.px = np.ascontiguousarray(pen.transpose(2, 0, 1))
        self.py = np.ascontiguousarray(pen.transpose(1, 0, 2))
        del pen
        self.step, self.turn = step_cost, turn_cost
        self.seeds = seeds
        self.out_x = np.empty_like(self.px)
        self.out_y = np.empty_like(self.py)
        self.acc_y = np.empty_like(self.py)
        self.vy = np.empty_like(self.py)

    def __call__(self, cost, after, best) -> None:
        """``best`` (x layout) = min(best, cheapest run + ``after`` where it ends), per state;
        ``after`` is patched at the seeds for each kind of run and restored."""
        sd = self.seeds
        diag = self.step * math.sqrt(2.0)
        cx = cost.reshape(-1)[sd.at_x]
        ax = after.reshape(-1)
        for sign in (1, -1):
            for lateral, w in ((0, self.step), (1, diag), (-1, diag)):
                sd.patch(ax, sd.at_x, cx, _MOVES8.index((sign, lateral)))
                _sweep(after, self.px, sign, ((lateral, w),), best, self.out_x)
        np.copyto(self.vy, after.transpose(2, 1, 0))
        ay = self.vy.reshape(-1)
        self.acc_y.fill(np.inf)
        for sign in (1, -1):
            sd.patch(ay, sd.at_y, cx, _MOVES8.index((0, sign)))
            _sweep(self.vy, self.py, sign, ((0, self.step),), self.acc_y, self.out_y)
        np.minimum(best, self.acc_y.transpose(2, 1, 0), out=best)
        if self.k_bins > 1:
            sd.patch(ax, sd.at_x, cx, 8)
            self._turns(after, best)
        sd.patch(ax, sd.at_x, cx, None)

    def _turns(self, after, best) -> None:
        out, k_bins = self.out_x, self.k_bins
        for up in (True, False):
            out[:, 0 if up else k_bins - 1] = np.inf
            order = range(2 * k_bins - 1, -1, -1) if up else range(2 * k_bins)
            for i in order:
                k = i % k_bins
                k2 = (k + (1 if up else -1)) % k_bins
                r = out[:, k]
                np.minimum(after[:, k2], out[:, k2], out=r)
                r += self.turn
                r += self.px[:, k]
                b = best[:, k]
                np.minimum(b, r, out=b)


def lattice_cost_to_go(
    free: BoolArray,
    seeds: tuple[NDArray[np.int_], FloatArray],
    step_cost: float,
    turn_cost: float,
    manipulation_cost: float = 0.0,
    max_rounds: int = 8,
    seed_kinds: NDArray[np.int_] | None = None,
) -> FloatArray:
    """(D) Cheapest cost (s) from every state of a (K, ny, nx) lattice to the goal.

    free: the free states; moves: 8-connected one-cell steps within a heading layer (``step_cost``
    s straight, ``sqrt(2)`` times that diagonally) and one heading bin in place, wrapping
    (``turn_cost`` s), between free states. seeds: goal states (m, 3) as (k, iy, ix) with the
    cost (m,) s still to pay from each (the final move to the exact goal pose). Every change of
    the kind of move (a new translation direction of :data:`_MOVES8`, or between translating
    and turning) costs ``manipulation_cost`` s; the value is the cost with the first move's kind
    free (a start). ``seed_kinds`` (m,): the kind each seed's way to the goal begins with (0-7 a
    direction, 8 turning, -1 none): arriving by another kind adds the manipulation cost.
    Returns inf where no seed can be reached.

    First the cost without the manipulation cost, by a vectorised Dijkstra, plus the fewest
    changes of direction of the (x, y) walk (:func:`turn_bounds`); then value iteration over
    straight runs: the cost from a state is the cheapest straight run (one direction, or turning
    one way) to a state where the goal is joined, or where the robots re-arrange
    (``manipulation_cost``) and start afresh. Each round is one sweep per direction
    (:func:`_sweep`) in float32; every round is a lower bound (the larger is kept), and the
    rounds reach the fixed point in as many rounds as the routes have runs (``max_rounds`` caps
    them; what is left is still a lower bound).
    """
    join = _seed_table(free.shape, seeds)
    cost = _mode_free_cost_to_go(free, join, step_cost, turn_cost)
    if manipulation_cost <= 0:
        return cost
    # a tighter start: every change of translation direction of the (x, y) walk is charged
    _, links = turn_bounds(free.any(axis=0), np.isfinite(join).any(axis=0), _MOVES8_ARRAY)
    cost = cost + manipulation_cost * np.where(np.isfinite(links), links, 0.0)[None]
    # rounds in float32, in the (nx, K, ny) layout of the sweeps
    cells = np.asarray(seeds[0], dtype=np.int64).reshape(-1, 3)
    kinds = np.full(len(cells), -1) if seed_kinds is None else np.asarray(seed_kinds)
    sd = _Seeds(cells, seeds[1], kinds, manipulation_cost, free.shape)
    runs = _RunCosts(free, step_cost, turn_cost, sd)
    cost = np.ascontiguousarray(cost.transpose(2, 0, 1), dtype=np.float32)
    join32 = np.ascontiguousarray(join.transpose(2, 0, 1), dtype=np.float32)
    after = np.empty_like(cost)
    new = np.empty_like(cost)
    for _ in range(max_rounds):
        np.add(cost, np.float32(manipulation_cost), out=after)
        np.minimum(after, join32, out=after)
        np.copyto(new, join32)
        runs(cost, after, new)
        new += runs.px
        np.maximum(new, cost, out=new)  # every round is a lower bound: keep the larger
        if np.array_equal(new, cost):
            break
        cost, new = new, cost
    del runs, after, new, join32
    # float32 rounding must not lift the bound above the true cost: a value is a sum of at most
    # one rounded addition per move (each costs >= the lightest move) and two per round, each
    # off by at most 2^-24 of the value; give that back
    out = cost.transpose(1, 2, 0).astype(np.float64)
    lightest = step_cost if free.shape[0] == 1 else min(step_cost, turn_cost)
    fin = np.isfinite(out)
    out[fin] -= out[fin] * (out[fin] / lightest + 2 * max_rounds + 4) * 2.0**-24
    return out


_MOVES8 = ((1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1))
_MOVES8_ARRAY = np.array(_MOVES8, dtype=int)


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
    free: BoolArray, goal: tuple[int, int] | BoolArray, moves: NDArray[np.int_]
) -> tuple[FloatArray, FloatArray]:
    """Fewest changes of travel direction to reach the goal (link distance), a manipulation bound.

    ``goal``: a cell (iy, ix) or a mask (ny, nx) of goal cells (0 changes needed there).
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
    if isinstance(goal, tuple):
        is_goal = np.zeros(n, dtype=bool)
        is_goal[goal[0] * nx + goal[1]] = True
    else:
        is_goal = np.asarray(goal, dtype=bool).ravel()
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
