"""Can the robots hold the object? Holding capacity of a set of frictionless contacts under force
limits, and the reinforcement of a capture set until it can hold.

Form closure (Sharma et al. 2007, §2; ``controller.planning.capture``) says that *some* positive
contact forces resist every disturbance; it says nothing of how large they must be. A set of
points in closure whose moment arms are short can need several times the push it resists
(seen: the GA's 4-point set on the L crate needs up to 32 N at a contact to resist a 4 N push),
and velocity-controlled robots resist only up to their ``max_force``. The live object pushes
with up to ``capture.hold_force`` N (and a torque of that force times its radius of gyration),
so the cage holds only if, for every such disturbance, the contact-force LP

    find f:  W f = -w,  0 ≤ f_i ≤ max_force_i        (W: the contacts' unit wrenches)

is feasible. ``holding_capacity`` is the largest scale ``s`` for which every disturbance
``s·w_d`` of a polytope around the disturbance set is resisted: one LP over all of them (HiGHS);
``s ≥ 1`` holds. ``reinforce`` adds contact points (greedily, with a look-ahead of two) from the
capture's candidate nodes until the set holds or no robots are left.

Pure: arrays in, results out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

FloatArray = NDArray[np.float64]
DIRECTIONS = 16  # force directions of the disturbance polytope (each with -τ, 0, +τ)
MAX_SCALE = 100.0


def contact_wrenches(points: FloatArray, normals: FloatArray, centroid: FloatArray) -> FloatArray:
    """Unit wrenches (3, n) of robots pushing at ``points`` along ``-normals`` (outward normals),
    moments about ``centroid``."""
    f = -np.asarray(normals, float)
    rel = np.asarray(points, float) - np.asarray(centroid, float)
    return np.vstack([f.T, rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]])


def disturbances(force: float, torque: float, directions: int = DIRECTIONS) -> FloatArray:
    """Vertices (k, 3) of a polytope around {|F| ≤ force, |τ| ≤ torque}: ``directions`` forces
    on a circle circumscribing the disc, each with -torque, 0 and +torque."""
    ang = np.linspace(0.0, 2.0 * np.pi, directions, endpoint=False)
    r = force / np.cos(np.pi / directions)
    out = [[r * np.cos(a), r * np.sin(a), s * torque] for a in ang for s in (-1.0, 0.0, 1.0)]
    return np.asarray(out, float)


def holding_profile(wrenches: FloatArray, max_force: FloatArray, load: FloatArray) -> FloatArray:
    """Per disturbance ``d`` the largest ``s_d`` (capped at ``MAX_SCALE``) such that ``s_d·load[d]``
    is resisted by contact forces in ``[0, max_force]`` (0: that direction cannot be resisted at
    all). The directions are independent, so one LP maximising their sum gives each its own."""
    w = np.asarray(wrenches, float)
    n = w.shape[1]
    k = len(load)
    if n == 0:
        return np.zeros(k)
    nv = k * n + k
    a = np.zeros((3 * k, nv))
    for d in range(k):
        a[3 * d : 3 * d + 3, d * n : (d + 1) * n] = w
        a[3 * d : 3 * d + 3, k * n + d] = load[d]
    bounds = [(0.0, _upper(f)) for f in np.tile(np.asarray(max_force, float), k)]
    bounds += [(0.0, MAX_SCALE)] * k
    c = np.zeros(nv)
    c[k * n :] = -1.0
    res = linprog(c, A_eq=a, b_eq=np.zeros(3 * k), bounds=bounds, method="highs")
    return np.asarray(res.x[k * n :], float) if res.status == 0 else np.zeros(k)


def _upper(f: float) -> float | None:
    return float(f) if np.isfinite(f) else None  # a wall pushes as hard as it is pushed


def holding_capacity(wrenches: FloatArray, max_force: FloatArray, load: FloatArray) -> float:
    """The largest ``s`` such that every disturbance ``s·load[d]`` is resisted by contact forces
    in ``[0, max_force]``: ``s ≥ 1`` holds; 0 when some direction cannot be resisted at all (the
    set is not in closure)."""
    return float(holding_profile(wrenches, max_force, load).min(initial=MAX_SCALE))


@dataclass(frozen=True)
class Reinforced:
    """A capture set reinforced to hold: node indices, their capacity, and whether it holds."""

    chosen: np.ndarray
    capacity: float
    holds: bool
    added: int


def reinforce(
    points: FloatArray,
    normals: FloatArray,
    centroid: FloatArray,
    chosen: np.ndarray,
    allowed: NDArray[np.bool_],
    conflict: NDArray[np.bool_],
    max_force: float,
    load: FloatArray,
    robots: int,
    max_passes: int = 4,
    fixed: FloatArray | None = None,
    locked: int = 0,
) -> Reinforced:
    """Add candidate nodes (indices into ``points``) to ``chosen`` until the set holds ``load``
    (capacity ≥ 1) or it has ``robots`` points; if it still does not hold, move one point at a
    time to another node while that raises the capacity (at most ``max_passes`` passes).

    Points are ranked by the worst direction's capacity, ties broken by the mean over the
    directions (so a node that only pays with a partner still ranks); a node must be
    ``allowed`` and clear of the others (``conflict``: robot discs too close). ``fixed`` (3, k)
    are unit wrenches of contacts that are always there and push as hard as needed (walls the
    object is pressed against)."""
    idx = [int(i) for i in chosen]
    score = _scorer(points, normals, centroid, max_force, load, fixed)
    cap = score(idx)
    added = 0
    while cap[0] < 1.0 and len(idx) < robots:
        free = _free(idx, allowed, conflict)
        best = max(((score(idx + [j]), j) for j in free), default=None, key=lambda s: s[0])
        if best is None or best[0] <= cap:
            break
        cap, j = best
        idx.append(j)
        added += 1
    for _ in range(max_passes):
        if cap[0] >= 1.0:
            break
        idx, better = _swap_pass(idx, cap, score, allowed, conflict, locked)
        if better <= cap:
            break
        cap = better
    return Reinforced(np.asarray(idx, int), cap[0], cap[0] >= 1.0, added)


def _scorer(points, normals, centroid, max_force, load, fixed=None):
    extra = np.zeros((3, 0)) if fixed is None else np.asarray(fixed, float)

    def score(sel: list[int]) -> tuple[float, float]:
        w = np.hstack([contact_wrenches(points[sel], normals[sel], centroid), extra])
        limits = np.r_[np.full(len(sel), max_force), np.full(extra.shape[1], np.inf)]
        prof = holding_profile(w, limits, load)
        return float(prof.min()), float(prof.mean())

    return score


def _free(idx: list[int], allowed, conflict) -> list[int]:
    return [int(j) for j in np.flatnonzero(allowed) if j not in idx and not conflict[j, idx].any()]


def _swap_pass(idx, cap, score, allowed, conflict, locked=0):
    """One pass of single-point moves (the first ``locked`` points stay), keeping every one
    that raises the capacity."""
    best = cap
    for i in range(locked, len(idx)):
        others = idx[:i] + idx[i + 1 :]
        for j in _free(others, allowed, conflict):
            trial = others[:i] + [j] + others[i:]
            s = score(trial)
            if s > best:
                idx, best = trial, s
                break
    return idx, best


def wall_contacts(
    polygon_world: FloatArray,
    obstacles: list[FloatArray],
    bounds: FloatArray | None,
    tolerance: float,
) -> tuple[FloatArray, FloatArray]:
    """Where static things touch the object: its vertices within ``tolerance`` m of an obstacle
    or a wall, each with the direction (unit, world frame) the obstacle pushes it (away from
    the obstacle). A frictionless wall resists only along that normal. Returns (k, 2), (k, 2)."""
    from controller import geometry

    pts, pushes = [], []
    for v in np.asarray(polygon_world, float):
        for o in obstacles:
            o = np.asarray(o, float)
            d, closest = geometry.point_segment_distance(v[None], o, np.roll(o, -1, axis=0))
            j = int(np.argmin(d[0]))
            if d[0, j] <= tolerance:
                away = v - closest[0, j]
                nrm = np.linalg.norm(away)
                if nrm < 1e-9:  # on the boundary: the edge's outward normal
                    e = np.roll(o, -1, axis=0)[j] - o[j]
                    away = np.array([e[1], -e[0]])
                    if geometry.signed_area(o) < 0:
                        away = -away
                pts.append(v)
                pushes.append(away / np.linalg.norm(away))
        if bounds is not None:
            (x0, y0), (x1, y1) = np.asarray(bounds, float)
            for dist, push in (
                (v[0] - x0, (1.0, 0.0)),
                (x1 - v[0], (-1.0, 0.0)),
                (v[1] - y0, (0.0, 1.0)),
                (y1 - v[1], (0.0, -1.0)),
            ):
                if dist <= tolerance:
                    pts.append(v)
                    pushes.append(np.array(push))
    return np.reshape(pts, (-1, 2)), np.reshape(pushes, (-1, 2))


def push_wrenches(points: FloatArray, pushes: FloatArray, centroid: FloatArray) -> FloatArray:
    """Unit wrenches (3, k) of forces along ``pushes`` applied at ``points`` (same frame)."""
    f = np.asarray(pushes, float).reshape(-1, 2)
    rel = np.asarray(points, float).reshape(-1, 2) - np.asarray(centroid, float)
    return np.vstack([f.T, rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]])


def least_force_set(
    points: FloatArray,
    normals: FloatArray,
    centroid: FloatArray,
    wrench: FloatArray,
    max_force: float,
    conflict: NDArray[np.bool_],
) -> np.ndarray:
    """Candidate nodes (indices) that produce ``wrench`` (Fx, Fy, τ about ``centroid``) with the
    least total contact force within ``max_force`` each: the L1 LP over every candidate at once,
    whose basic solution uses at most three contacts. Nodes in conflict with a node carrying more
    force are dropped (the caller reinforces the rest); empty when no forces produce the wrench."""
    w = contact_wrenches(points, normals, centroid)
    n = w.shape[1]
    res = linprog(
        np.ones(n),
        A_eq=w,
        b_eq=np.asarray(wrench, float),
        bounds=[(0.0, float(max_force))] * n,
        method="highs",
    )
    if res.status != 0:
        return np.zeros(0, int)
    order = np.argsort(-res.x)
    keep: list[int] = []
    for j in order:
        if res.x[j] <= 1e-9:
            break
        if not conflict[j, keep].any():
            keep.append(int(j))
    return np.asarray(keep, int)
