"""Capture points in form closure by a genetic algorithm (Sharma et al. 2007, §2 and §4.1).

Definitions follow the capture issue (they stand over the paper):

- Candidate nodes along each counter-clockwise edge at ``spacing``; a node is dropped when a
  robot disc of radius r at ``p + (r + clearance)·n`` would overlap the object.
- A robot at node i pushes with ``−n_i``; its moment about the area centroid c is
  ``m_i = cross(p_i − c, −n_i)``. ``N_ccw = #{m > τ}``, ``N_cw = #{m < −τ}``; ``M_ccw``, ``M_cw``
  the sums of those moments.
- Objective ``f = (|M_cw| + |M_ccw|) / N^k · 1 / (|N_cw − N_ccw| + ε)``.
- Paper constraints: the push normals positively span the plane (translation closure), moments
  both ways, at most one robot per edge, robot centres ``p + r·n`` at least ``2r + clearance``
  apart. Violations get the paper's penalty −1e20.
- ``closure = "exact"`` also demands first-order form closure: the wrenches ``(−n_i, m_i)``
  positively span R³ (checked in the GA by supporting planes through pairs of wrenches, and
  certified at the end by an LP). On polygons with fewer than four edges the one-per-edge rule
  yields (frictionless planar form closure needs four contacts).

The GA: binary strings (one bit per node), the whole population evaluated at once with numpy,
tournament selection, two-point crossover, mutation as moves of a robot along the boundary
(or adding/removing one), elitism, and a local search of the best string's one-move
neighbours inside the same evaluation budget. Pure: arrays in, results out, a seeded generator.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment, linprog

from controller import geometry

FloatArray = NDArray[np.float64]
PENALTY = -1e20
MAX_SET = 8  # the largest robot set whose closure the GA checks (more bits: infeasible)


@dataclass(frozen=True)
class CaptureParams:
    spacing: float = 0.1
    clearance: float = 0.02
    k: float = 1.0
    epsilon: float = 0.1
    tau: float = 1e-9
    population: int = 60
    crossover: float = 0.8
    mutation: float = 0.12
    generations: int = 600
    closure: str = "exact"

    @classmethod
    def from_config(cls, c) -> CaptureParams:
        return cls(
            spacing=c.spacing,
            clearance=c.clearance,
            k=c.k,
            epsilon=c.epsilon,
            tau=c.tau,
            population=c.population,
            crossover=c.crossover,
            mutation=c.mutation,
            generations=c.generations,
            closure=c.closure,
        )


@dataclass(frozen=True)
class Candidates:
    points: FloatArray  # (K, 2) object frame
    normals: FloatArray  # (K, 2) outward unit normals
    edges: NDArray[np.int64]  # (K,) edge index
    n_edges: int


def candidate_nodes(
    polygon: FloatArray, robot_radius: float, spacing: float, clearance: float
) -> Candidates:
    """Nodes along each edge of the (counter-clockwise) polygon, those a robot disc fits at."""
    poly = geometry.ensure_ccw(polygon)
    a = poly
    b = np.roll(poly, -1, axis=0)
    normals = geometry.outward_normals(poly)
    pts, nrm, edg = [], [], []
    for e in range(len(poly)):
        length = float(np.linalg.norm(b[e] - a[e]))
        m = max(1, int(np.floor(length / spacing + 1e-9)))
        s = (np.arange(m) + 0.5) / m
        pts.append(a[e] + s[:, None] * (b[e] - a[e]))
        nrm.append(np.repeat(normals[e][None], m, axis=0))
        edg.append(np.full(m, e))
    p, n, ed = np.concatenate(pts), np.concatenate(nrm), np.concatenate(edg)
    centres = p + (robot_radius + clearance) * n
    keep = ~geometry.discs_hit_polygon(centres, robot_radius, poly)
    return Candidates(p[keep], n[keep], ed[keep], len(poly))


@dataclass
class Problem:
    """Everything the objective needs, precomputed per node and per node pair."""

    cand: Candidates
    centroid: FloatArray
    moments: FloatArray  # (K,)
    ccw: FloatArray  # (K,) 1.0 where m > tau
    cw: FloatArray
    conflict: NDArray[np.bool_]  # (K, K) robot discs too close
    wrench: FloatArray  # (K, 3)
    angles: FloatArray  # (K,) push direction angles
    one_per_edge: bool
    params: CaptureParams
    n_robots_note: str = ""
    side_neg: NDArray[np.bool_] | None = None  # (K, K, K) wrench i below the plane of (a, b)
    side_pos: NDArray[np.bool_] | None = None
    pair_plane: NDArray[np.bool_] | None = None  # (K, K) the pair spans a plane


def make_problem(
    polygon: FloatArray,
    robot_radius: float,
    params: CaptureParams,
    cand: Candidates | None = None,
) -> Problem:
    """The GA's problem; ``cand`` replaces the candidate nodes (hand-made contact sets)."""
    poly = geometry.ensure_ccw(polygon)
    if cand is None:
        cand = candidate_nodes(poly, robot_radius, params.spacing, params.clearance)
    c = geometry.centroid(poly)
    f = -cand.normals
    rel = cand.points - c
    m = rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]
    centres = cand.points + robot_radius * cand.normals
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = d < 2 * robot_radius + params.clearance - 1e-12
    np.fill_diagonal(conflict, False)
    one_per_edge = not (params.closure == "exact" and len(poly) < 4)
    note = (
        ""
        if one_per_edge
        else "polygon has fewer than 4 edges: the one-robot-per-edge rule yields to the spacing "
        "rule (planar form closure needs 4 frictionless contacts)"
    )
    wrench = np.column_stack([f, m])
    neg, pos, plane = _side_tables(wrench)
    return Problem(
        side_neg=neg,
        side_pos=pos,
        pair_plane=plane,
        cand=cand,
        centroid=c,
        moments=m,
        ccw=(m > params.tau).astype(float),
        cw=(m < -params.tau).astype(float),
        conflict=conflict,
        wrench=wrench,
        angles=np.arctan2(f[:, 1], f[:, 0]),
        one_per_edge=one_per_edge,
        params=params,
        n_robots_note=note,
    )


# --------------------------------------------------------------------------- evaluation


def _chosen_index(x: NDArray[np.bool_], size: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Indices of the set bits of each row, padded to ``size`` (mask says which are real)."""
    order = np.argsort(~x, axis=1, kind="stable")[:, :size]
    mask = np.take_along_axis(x, order, axis=1)
    return order, mask


def translation_closure(prob: Problem, x: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Push directions positively span the plane: the largest angular gap is below π."""
    ang = np.where(x, prob.angles[None], np.inf)
    s = np.sort(ang, axis=1)
    cnt = x.sum(1)
    ok = np.zeros(len(x), bool)
    for c in np.unique(cnt):
        if c < 3:
            continue
        rows = cnt == c
        a = s[rows, :c]
        gaps = np.diff(np.concatenate([a, a[:, :1] + 2 * np.pi], axis=1), axis=1)
        ok[rows] = gaps.max(1) < np.pi - 1e-9
    return ok


def wrench_closure(prob: Problem, x: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """First-order form closure: the wrenches positively span R³. A set fails iff some closed
    half-space holds them all; its boundary plane can be taken through two of them (a set of
    rank ≤ 2 lies in such a plane; rank ≤ 1 fails translation closure before this check). The
    sign of every wrench against every pair's plane is tabulated once per problem."""
    cnt = x.sum(1)
    ok = np.zeros(len(x), bool)
    rows = np.flatnonzero((cnt >= 4) & (cnt <= MAX_SET))
    if len(rows) == 0:
        return ok
    size = int(cnt[rows].max())
    idx, mask = _chosen_index(x[rows], size)
    a = idx[:, :, None, None]
    b = idx[:, None, :, None]
    i = idx[:, None, None, :]
    real = mask[:, None, None, :]
    neg = np.any(prob.side_neg[a, b, i] & real, axis=-1)
    pos = np.any(prob.side_pos[a, b, i] & real, axis=-1)
    pair_ok = (
        mask[:, :, None] & mask[:, None, :] & prob.pair_plane[idx[:, :, None], idx[:, None, :]]
    )
    one_side = pair_ok & ~(neg & pos)
    ok[rows] = ~one_side.any(axis=(1, 2))
    return ok


def _side_tables(wrench: FloatArray, tol: float = 1e-9):
    """Signs of every wrench against the plane through every pair of wrenches (unit-scaled)."""
    w = wrench / np.maximum(np.linalg.norm(wrench, axis=1, keepdims=True), 1e-12)
    y = np.cross(w[:, None, :], w[None, :, :])  # (K, K, 3)
    d = np.einsum("abk,ik->abi", y, w)
    return d < -tol, d > tol, np.linalg.norm(y, axis=-1) > 1e-9


def evaluate(prob: Problem, x: NDArray[np.bool_]) -> tuple[FloatArray, NDArray[np.int64]]:
    """Objective of every string (P, K) and its count of violated constraints (0: feasible)."""
    p = prob.params
    xf = x.astype(float)
    n = xf.sum(1)
    n_ccw = xf @ prob.ccw
    n_cw = xf @ prob.cw
    m_ccw = xf @ (prob.moments * prob.ccw)
    m_cw = xf @ (prob.moments * prob.cw)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (
            (np.abs(m_cw) + np.abs(m_ccw))
            / np.maximum(n, 1) ** p.k
            / (np.abs(n_cw - n_ccw) + p.epsilon)
        )
    viol = np.zeros(len(x), dtype=np.int64)
    viol += n < 3
    viol += ~translation_closure(prob, x)
    viol += (n_ccw < 1) | (n_cw < 1)
    if prob.one_per_edge:
        per_edge = np.zeros((len(x), prob.cand.n_edges))
        np.add.at(per_edge.T, prob.cand.edges, xf.T)
        viol += np.any(per_edge > 1, axis=1)
    viol += ((xf @ prob.conflict.astype(float)) * xf).sum(1) > 0
    if p.closure == "exact":
        cheap_ok = viol == 0
        closed = np.zeros(len(x), bool)
        if np.any(cheap_ok):
            closed[cheap_ok] = wrench_closure(prob, x[cheap_ok])
        viol += ~closed
    f = np.where(viol == 0, f, PENALTY)
    return f, viol


def certify_form_closure(points: FloatArray, normals: FloatArray, centroid: FloatArray) -> bool:
    """LP certificate of first-order form closure: rank 3 and λ ≥ 1 with Σ λ_i w_i = 0."""
    f = -np.asarray(normals, float)
    rel = np.asarray(points, float) - centroid
    m = rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]
    w = np.vstack([f.T, m])  # (3, n)
    if len(f) < 4 or np.linalg.matrix_rank(w) < 3:
        return False
    res = linprog(
        np.ones(len(f)), A_eq=w, b_eq=np.zeros(3), bounds=[(1.0, None)] * len(f), method="highs"
    )
    return bool(res.status == 0)


# --------------------------------------------------------------------------- the GA


def _initial(k: int, size: int, rng: np.random.Generator, lo: int = 3, hi: int = 6) -> np.ndarray:
    x = np.zeros((size, k), bool)
    for r in range(size):
        x[r, rng.choice(k, size=min(k, int(rng.integers(lo, hi + 1))), replace=False)] = True
    return x


def _mutate(x: np.ndarray, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Per child with probability ``rate``: move one robot 1–2 nodes along the boundary (70 %),
    jump it anywhere (10 %), add one (10 %) or remove one (10 %; never below three)."""
    p, k = x.shape
    out = x.copy()
    rows = np.flatnonzero(rng.random(p) < rate)
    if len(rows) == 0:
        return out
    sub = out[rows]
    cnt = sub.sum(1)
    pick = np.argmax(rng.random((len(rows), k)) * sub, axis=1)  # a random set bit
    u = rng.random(len(rows))
    shift = np.array([-2, -1, 1, 2])[rng.integers(0, 4, len(rows))]
    target = np.where(u < 0.7, (pick + shift) % k, rng.integers(0, k, len(rows)))
    r = np.arange(len(rows))
    move = (u < 0.8) & (cnt > 0)
    add = ~move & ((u < 0.9) | (cnt <= 3))
    remove = ~move & ~add
    sub[r[move], pick[move]] = False
    sub[r[move | add], target[move | add]] = True
    sub[r[remove], pick[remove]] = False
    out[rows] = sub
    return out


def _neighbours(best: np.ndarray) -> np.ndarray:
    """Every one-move neighbour of a string: one robot relocated to any free node."""
    on = np.flatnonzero(best)
    off = np.flatnonzero(~best)
    out = np.repeat(best[None], len(on) * len(off), axis=0)
    r = np.arange(len(out))
    out[r, np.repeat(on, len(off))] = False
    out[r, np.tile(off, len(on))] = True
    return out


@dataclass
class GAResult:
    best: np.ndarray
    objective: float
    evaluations: int
    history: list[float] = field(default_factory=list)


def run_ga(
    prob: Problem, rng: np.random.Generator, objective=None, stall: int = 40, init=(3, 6)
) -> GAResult:
    """The GA on ``prob`` (objective ``evaluate`` unless another (f, viol) function is given).

    Within the budget (population × generations evaluations) a run that has converged (no
    better string for ``stall`` generations and its best string's neighbourhood searched)
    restarts from a fresh population; the best string ever found is the answer.
    """
    p = prob.params
    fn = objective or (lambda x: evaluate(prob, x))
    k = len(prob.cand.points)
    pop_n = p.population
    pop = _initial(k, pop_n, rng, *init)
    f, v = fn(pop)
    evals = pop_n
    history: list[float] = []
    best_x, best_f = pop[0].copy(), -np.inf
    run_best, since = -np.inf, 0
    queue = np.zeros((0, k), bool)
    queue_of = b""
    for _ in range(p.generations):
        # rank: feasible by objective, infeasible by fewer violations
        key = np.where(v == 0, f, -1e30 - v)
        elite = int(np.argmax(key))
        best = pop[elite]
        if v[elite] == 0 and f[elite] > best_f:
            best_x, best_f = best.copy(), float(f[elite])
        if v[elite] == 0 and f[elite] > run_best + 1e-12:
            run_best, since = float(f[elite]), 0
        else:
            since += 1
        # local search: the best feasible string's relocation neighbours, a slice per
        # generation (inside the budget) until they are exhausted or a better one turns up
        if v[elite] == 0 and best.tobytes() != queue_of:
            queue = _neighbours(best)
            queue = queue[rng.permutation(len(queue))]
            queue_of = best.tobytes()
        if since >= stall and len(queue) == 0:
            # converged: restart (the best ever is kept aside)
            new = _initial(k, pop_n - 1, rng, *init)
            run_best, since, queue_of = -np.inf, 0, b""
        else:
            nb = queue[: pop_n // 2]
            queue = queue[pop_n // 2 :]
            n_child = pop_n - 1 - len(nb)
            # tournament selection (size 2)
            a = rng.integers(pop_n, size=(n_child, 2))
            pa = np.where(key[a[:, 0]] >= key[a[:, 1]], a[:, 0], a[:, 1])
            b = rng.integers(pop_n, size=(n_child, 2))
            pb = np.where(key[b[:, 0]] >= key[b[:, 1]], b[:, 0], b[:, 1])
            kids = pop[pa].copy()
            cross = rng.random(n_child) < p.crossover
            cuts = np.sort(rng.integers(0, k + 1, size=(n_child, 2)), axis=1)
            cols = np.arange(k)[None]
            seg = (cols >= cuts[:, :1]) & (cols < cuts[:, 1:]) & cross[:, None]
            kids[seg] = pop[pb][seg]
            kids = _mutate(kids, p.mutation, rng)
            new = np.vstack([nb, kids])
        fn_new, v_new = fn(new)
        evals += len(new)
        pop = np.vstack([best[None], new])
        f = np.concatenate([[f[elite]], fn_new])
        v = np.concatenate([[v[elite]], v_new])
        if since == 0 and run_best == -np.inf:  # a restart: the old elite leaves the population
            pop, f, v = pop[1:], f[1:], v[1:]
            pop = np.vstack([pop, _initial(k, 1, rng, *init)])
            f1, v1 = fn(pop[-1:])
            f, v = np.concatenate([f, f1]), np.concatenate([v, v1])
            evals += 1
        cur = np.where(v == 0, f, -np.inf).max()
        if cur > best_f:
            best_x, best_f = pop[int(np.argmax(np.where(v == 0, f, -np.inf)))].copy(), float(cur)
        history.append(best_f if np.isfinite(best_f) else PENALTY)
    return GAResult(best_x, best_f if np.isfinite(best_f) else PENALTY, evals, history)


# --------------------------------------------------------------------------- results


@dataclass
class CapturePlan:
    candidates: FloatArray
    normals: FloatArray
    edges: NDArray[np.int64]
    chosen: NDArray[np.int64]
    points: FloatArray  # (M, 2) object frame
    push_normals: FloatArray  # (M, 2) outward normals at the points (robots push along −n)
    robots_needed: int
    objective: float
    M_cw: float
    M_ccw: float
    N_cw: int
    N_ccw: int
    paper_feasible: bool
    form_closure: bool
    evaluations: int
    history: list[float]
    closure: str
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "candidates": self.candidates.round(6).tolist(),
            "normals": self.normals.round(6).tolist(),
            "edges": self.edges.tolist(),
            "chosen": self.chosen.tolist(),
            "points": self.points.round(6).tolist(),
            "robots_needed": self.robots_needed,
            "objective": self.objective,
            "M_cw": self.M_cw,
            "M_ccw": self.M_ccw,
            "N_cw": self.N_cw,
            "N_ccw": self.N_ccw,
            "paper_feasible": self.paper_feasible,
            "form_closure": self.form_closure,
            "closure": self.closure,
            "evaluations": self.evaluations,
            "history": [float(h) for h in self.history],
            "note": self.note,
        }


def describe(
    prob: Problem, bits: np.ndarray, evaluations: int, history: list[float]
) -> CapturePlan:
    """The plan for a chosen string, with the paper's check and the exact certificate."""
    chosen = np.flatnonzero(bits)
    f, v = evaluate(prob, bits[None])
    paper = CaptureParams(**{**prob.params.__dict__, "closure": "paper"})
    _, v_paper = evaluate(Problem(**{**prob.__dict__, "params": paper}), bits[None])
    m = prob.moments[chosen]
    pts = prob.cand.points[chosen]
    nrm = prob.cand.normals[chosen]
    return CapturePlan(
        candidates=prob.cand.points,
        normals=prob.cand.normals,
        edges=prob.cand.edges,
        chosen=chosen,
        points=pts,
        push_normals=nrm,
        robots_needed=len(chosen),
        objective=float(f[0]),
        M_cw=float(m[m < -prob.params.tau].sum()),
        M_ccw=float(m[m > prob.params.tau].sum()),
        N_cw=int((m < -prob.params.tau).sum()),
        N_ccw=int((m > prob.params.tau).sum()),
        paper_feasible=bool(v_paper[0] == 0),
        form_closure=certify_form_closure(pts, nrm, prob.centroid),
        evaluations=evaluations,
        history=history,
        closure=prob.params.closure,
        note=prob.n_robots_note,
    )


def plan_capture(
    polygon: FloatArray, robot_radius: float, params: CaptureParams, rng: np.random.Generator
) -> CapturePlan:
    """Capture points for a polygon (object frame) by the GA."""
    prob = make_problem(polygon, robot_radius, params)
    if len(prob.cand.points) < 3:
        raise ValueError(
            f"only {len(prob.cand.points)} candidate nodes: capture.spacing is too coarse for "
            "this object or the robots are too large"
        )
    res = run_ga(prob, rng)
    return describe(prob, res.best, res.evaluations, res.history)


def brute_force_capture(
    polygon: FloatArray, robot_radius: float, params: CaptureParams, sizes=range(3, 7)
) -> tuple[float, np.ndarray]:
    """The exact optimum over node subsets of the given sizes (vectorized per chunk)."""
    prob = make_problem(polygon, robot_radius, params)
    k = len(prob.cand.points)
    best_f, best = PENALTY, np.zeros(k, bool)
    for s in sizes:
        if s > k:
            break
        combos = itertools.combinations(range(k), s)
        while True:
            chunk = np.fromiter(
                itertools.chain.from_iterable(itertools.islice(combos, 100_000)), dtype=np.int64
            ).reshape(-1, s)
            if len(chunk) == 0:
                break
            x = np.zeros((len(chunk), k), bool)
            np.put_along_axis(x, chunk, True, axis=1)
            f, _ = evaluate(prob, x)
            i = int(np.argmax(f))
            if f[i] > best_f:
                best_f, best = float(f[i]), x[i].copy()
    return best_f, best


# --------------------------------------------------------------------------- Eq. 5 and assignment


def push_objective(
    cand: Candidates,
    direction: FloatArray,
    n: int,
    conflict: NDArray[np.bool_],
    x: NDArray[np.bool_],
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Eq. 5: D·ΣF_i over strings of exactly n nodes, spacing kept, D inside the cone of the
    chosen push directions."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    f_push = -cand.normals
    xf = x.astype(float)
    val = xf @ (f_push @ d)
    viol = (xf.sum(1) != n).astype(np.int64)
    viol += ((xf @ conflict.astype(float)) * xf).sum(1) > 0
    # D in cone(F): some chosen F on each side of D (or along it) within a half-turn
    psi = np.arctan2(f_push[:, 0] * d[1] - f_push[:, 1] * d[0], f_push @ d)  # angle F → D
    along = np.abs(psi) < 1e-9
    left = np.where(x & (psi > 0), psi, np.inf).min(1)
    right = np.where(x & (psi < 0), -psi, np.inf).min(1)
    in_cone = np.any(x & along[None], axis=1) | (left + right <= np.pi)
    viol += ~in_cone
    return np.where(viol == 0, val, PENALTY), viol


def plan_push_arrangement(
    polygon: FloatArray,
    robot_radius: float,
    direction: FloatArray,
    n: int,
    params: CaptureParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, float]:
    """Eq. 5 by the GA: the n nodes (indices into the candidates) pushing hardest along D."""
    prob = make_problem(polygon, robot_radius, params)

    def fn(x: np.ndarray):
        return push_objective(prob.cand, direction, n, prob.conflict, x)

    res = run_ga(prob, rng, objective=fn, init=(n, n))  # strings start with exactly n robots
    return np.flatnonzero(res.best), res.objective


def brute_force_push(
    polygon: FloatArray, robot_radius: float, direction: FloatArray, n: int, params: CaptureParams
) -> tuple[np.ndarray, float]:
    prob = make_problem(polygon, robot_radius, params)
    k = len(prob.cand.points)
    combos = np.array(list(itertools.combinations(range(k), n)), dtype=np.int64)
    x = np.zeros((len(combos), k), bool)
    np.put_along_axis(x, combos, True, axis=1)
    f, _ = push_objective(prob.cand, direction, n, prob.conflict, x)
    i = int(np.argmax(f))
    return np.flatnonzero(x[i]), float(f[i])


def assign_robots(robot_xy: FloatArray, speed: FloatArray, targets: FloatArray) -> np.ndarray:
    """Robot index per target minimising the total travel time (straight lines, M ≤ N)."""
    robot_xy = np.asarray(robot_xy, float)
    targets = np.asarray(targets, float)
    if len(targets) > len(robot_xy):
        raise ValueError(f"{len(targets)} targets for {len(robot_xy)} robots")
    cost = np.linalg.norm(targets[:, None] - robot_xy[None], axis=-1) / np.asarray(speed)[None]
    rows, cols = linear_sum_assignment(cost)
    out = np.empty(len(targets), dtype=int)
    out[rows] = cols
    return out
