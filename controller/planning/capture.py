"""Capture points in form closure by a genetic algorithm (Sharma et al. 2007, §2 and §4.1).

Definitions follow the capture issues (they stand over the paper):

- Candidate nodes along each counter-clockwise edge at ``spacing``; a node is dropped when a
  robot disc of radius r at ``p + (r + clearance)·n`` would overlap the object.
- A robot at node i pushes with ``−n_i``; its moment about the area centroid c is
  ``m_i = cross(p_i − c, −n_i)``. ``N_ccw = #{m > τ}``, ``N_cw = #{m < −τ}``; ``M_ccw``, ``M_cw``
  the sums of those moments.
- Objective (Eq. 3) ``f = (|M_cw| + |M_ccw|) / N^k · 1 / (|N_cw − N_ccw| + ε)``.
- Paper constraints: the push normals positively span the plane (translation closure), moments
  both ways, at most one robot per edge, robot centres ``p + r·n`` at least ``2r + clearance``
  apart. Violations get the paper's penalty −1e20; for selection and elitism infeasible strings
  are ranked by their count of violated constraints (fewer first), feasible ones by f.
- The fleet: a plan uses at most ``max_robots`` robots (the fleet size); the closure test takes
  sets of up to ``MAX_CLOSURE_SET`` (200) robots. ``plan_for_fleet`` spaces robot centres by
  ``2r + max(capture.clearance, approach.safety_margin)``: the approach's safety filter keeps
  them that far apart, so closer points could never all be reached.
- ``closure = "exact"`` also demands first-order form closure: the wrenches ``(−n_i, m_i)``
  positively span R³ (checked in the GA by supporting planes through pairs of the chosen
  wrenches, and certified at the end by an LP). On polygons with fewer than four edges the
  one-per-edge rule yields (frictionless planar form closure needs four contacts).

Cost: the problem holds O(K) arrays for K candidate nodes (no pair or triple tables); every
constraint is checked on each string's chosen nodes only, O(n²) for the spacing and O(n³) for
the closure test with n the string's robot count, without matrix products (no BLAS threads).
The node count is bounded by ``controller.config.CAPTURE_NODE_BUDGET`` (a ``capture.spacing``
error at config load, an infeasible plan naming ``capture.spacing`` here).

The GA: binary strings (one bit per node) starting with 3–6 robots, the whole population
evaluated at once with numpy, tournament selection, two-point crossover, mutation (probability
``mutation`` per child) as moves of a robot along the boundary (or adding/removing one),
elitism, a local search of the best string's one-move neighbours, and a restart once a run has
stalled (``stall`` = 20 generations, tuned on a seeded suite the bench does not report), all
inside the budget of population × generations evaluations. Pure: arrays in, results out, a
seeded generator.

The outcome is a ``CapturePlan`` with ``feasible`` and a ``reason`` naming the constraint that
could not be met; an infeasible problem is never an exception.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment, linprog

from controller import geometry
from controller.config import (
    CAPTURE_NODE_BUDGET,
    CaptureSection,
    capture_budget_error,
    configured,
    edge_node_counts,
    from_section,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
PENALTY = -1e20  # the paper's penalty on an infeasible string's objective
INFEASIBLE_RANK = -1e30  # rank of an infeasible string: this times its violation count
# The closure test's memory grows with n³ for a string of n robots: it runs on rows in chunks of
# at most CLOSURE_CHUNK pair-against-wrench entries, and on strings of at most MAX_CLOSURE_SET
# robots (a larger set counts as not closed; the fleet limit is the working cap).
CLOSURE_CHUNK = 4_000_000
MAX_CLOSURE_SET = 200
# the constraints, in the order a diagnosis names them
CONSTRAINTS = ("robots", "fleet", "moments", "translation", "one_per_edge", "spacing", "closure")


_CAPTURE = CaptureSection()  # the config's defaults


@dataclass(frozen=True)
class CaptureParams:
    """The capture GA's parameters, each default the ``[capture]`` section's (``configured``);
    ``ga = "paper"``: run_paper_ga, Sharma's GA as published (the baseline)."""

    spacing: float = configured(_CAPTURE, "spacing")
    clearance: float = configured(_CAPTURE, "clearance")
    k: float = configured(_CAPTURE, "k")
    epsilon: float = configured(_CAPTURE, "epsilon")
    tau: float = configured(_CAPTURE, "tau")
    population: int = configured(_CAPTURE, "population")
    crossover: float = configured(_CAPTURE, "crossover")
    mutation: float = configured(_CAPTURE, "mutation")
    generations: int = configured(_CAPTURE, "generations")
    closure: str = configured(_CAPTURE, "closure")
    ga: str = configured(_CAPTURE, "ga")
    # m: nodes nearer a vertex than this are left out (the transport's error model: a robot
    # off by its motion error still pushes the face, never the corner; 0 for the capture)
    edge_margin: float = 0.0

    @classmethod
    def from_config(cls, c) -> CaptureParams:
        return from_section(cls, c)

    @property
    def min_robots(self) -> int:
        """Fewest robots that can satisfy the closure: 4 frictionless contacts for first-order
        form closure (exact), 3 for the paper's translation closure."""
        return 4 if self.closure == "exact" else 3


@dataclass(frozen=True)
class Candidates:
    points: FloatArray  # (K, 2) object frame
    normals: FloatArray  # (K, 2) outward unit normals
    edges: NDArray[np.int64]  # (K,) edge index
    n_edges: int
    total: int = 0  # nodes before the robot-disc test dropped any


def candidate_nodes(
    polygon: FloatArray,
    robot_radius: float,
    spacing: float,
    clearance: float,
    edge_margin: float = 0.0,
) -> Candidates:
    """Nodes along each edge of the (counter-clockwise) polygon, those a robot disc fits at;
    with ``edge_margin`` (m), only those at least that far from every vertex."""
    poly = geometry.ensure_ccw(polygon)
    budget = capture_budget_error(poly, spacing)
    if budget:
        raise ValueError(f"capture.spacing: {budget}")
    a = poly
    b = np.roll(poly, -1, axis=0)
    normals = geometry.outward_normals(poly)
    counts = edge_node_counts(poly, spacing).astype(np.int64)
    pts, nrm, edg = [], [], []
    for e, m in enumerate(counts):
        s = (np.arange(m) + 0.5) / m
        pts.append(a[e] + s[:, None] * (b[e] - a[e]))
        nrm.append(np.repeat(normals[e][None], m, axis=0))
        edg.append(np.full(m, e))
    p, n, ed = np.concatenate(pts), np.concatenate(nrm), np.concatenate(edg)
    centres = p + (robot_radius + clearance) * n
    keep = ~geometry.discs_hit_polygon(centres, robot_radius, poly)
    if edge_margin > 0:
        keep &= geometry.vertex_distance(p, poly) >= edge_margin - 1e-12
    return Candidates(p[keep], n[keep], ed[keep], len(poly), len(p))


@dataclass
class Problem:
    """Everything the objective needs, precomputed per node (O(K) memory)."""

    cand: Candidates
    centroid: FloatArray
    moments: FloatArray  # (K,)
    centres: FloatArray  # (K, 2) robot centres p + r·n
    min_gap: float  # 2r + clearance: the least distance between two robot centres
    wrench: FloatArray  # (K, 3)
    unit_wrench: FloatArray  # (K, 3) the wrenches scaled to unit length
    angles: FloatArray  # (K,) push direction angles
    one_per_edge: bool
    params: CaptureParams
    robot_radius: float = 0.0
    max_robots: int | None = None  # the fleet size (None: no limit)
    n_robots_note: str = ""
    table: FloatArray = field(default_factory=lambda: np.zeros((1, _COLUMNS)))  # node_table

    def __post_init__(self) -> None:
        self.table = node_table(self)


def make_problem(
    polygon: FloatArray,
    robot_radius: float,
    params: CaptureParams,
    cand: Candidates | None = None,
    max_robots: int | None = None,
) -> Problem:
    """The GA's problem; ``cand`` replaces the candidate nodes (hand-made contact sets);
    ``max_robots`` is the most robots a plan may use (the fleet size; None: no limit).
    Raises ValueError naming ``capture.spacing`` past the node budget."""
    poly = geometry.ensure_ccw(polygon)
    if cand is None:
        cand = candidate_nodes(
            poly, robot_radius, params.spacing, params.clearance, params.edge_margin
        )
    c = geometry.centroid(poly)
    f = -cand.normals
    rel = cand.points - c
    m = rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]
    one_per_edge = not (params.closure == "exact" and len(poly) < 4)
    note = (
        ""
        if one_per_edge
        else "polygon has fewer than 4 edges: the one-robot-per-edge rule yields to the spacing "
        "rule (planar form closure needs 4 frictionless contacts)"
    )
    wrench = np.column_stack([f, m])
    norm = np.sqrt((wrench * wrench).sum(axis=1, keepdims=True))
    return Problem(
        cand=cand,
        centroid=c,
        moments=m,
        centres=cand.points + robot_radius * cand.normals,
        min_gap=2 * robot_radius + params.clearance,
        wrench=wrench,
        unit_wrench=wrench / np.maximum(norm, 1e-12),
        angles=np.arctan2(f[:, 1], f[:, 0]),
        one_per_edge=one_per_edge,
        params=params,
        robot_radius=robot_radius,
        max_robots=max_robots,
        n_robots_note=note,
    )


# --------------------------------------------------------------------------- evaluation


_STEPS = np.arange(CAPTURE_NODE_BUDGET + 1)[None]  # 0, 1, 2, ... per node or robot (read only)
# columns of the per-node table (one extra all-padding row at index K)
_ABSM, _SIGN, _ANGLE, _CX, _CY, _EDGE = 0, 1, 2, 3, 4, 5
_W0, _W1, _W2 = 6, 7, 8  # the unit wrench
_COLUMNS = 9


def node_table(prob: Problem) -> FloatArray:
    """(K + 1, 9) per node: |moment| (0 when |m| ≤ τ), its sign (−1, 0, 1), push angle, robot
    centre x and y, edge, the unit wrench. Row K pads strings to a common length: no moment, an
    angle that sorts last, edge −1, no wrench."""
    k, tau = len(prob.cand.points), prob.params.tau
    m = prob.moments
    t = np.zeros((k + 1, _COLUMNS))
    t[:k, _ABSM] = np.where(np.abs(m) > tau, np.abs(m), 0.0)
    t[:k, _SIGN] = (m > tau).astype(float) - (m < -tau)
    t[:k, _ANGLE], t[:k, _CX], t[:k, _CY] = prob.angles, prob.centres[:, 0], prob.centres[:, 1]
    t[:k, _EDGE] = prob.cand.edges
    t[:k, _W0 : _W2 + 1] = prob.unit_wrench
    t[k, _ANGLE], t[k, _EDGE] = 10.0, -1.0
    return t


@dataclass
class _Chosen:
    """The chosen nodes of each string: indices ascending, padded with K to the largest count
    (P, n); their table rows (P, n, 8); the counts (P,)."""

    idx: NDArray[np.int64]
    t: FloatArray
    cnt: NDArray[np.int64]

    @classmethod
    def of(cls, prob: Problem, x: BoolArray) -> _Chosen:
        k = x.shape[1]
        cnt = np.count_nonzero(x, axis=1)
        size = int(cnt.max()) if len(x) else 0
        idx = np.full((len(x), size), k, np.int64)
        idx[_STEPS[:, :size] < cnt[:, None]] = x.ravel().nonzero()[0] % k  # row-major: in order
        return cls(idx, prob.table[idx], cnt)

    @property
    def mask(self) -> BoolArray:
        return _STEPS[:, : self.idx.shape[1]] < self.cnt[:, None]

    def rows(self, keep: BoolArray) -> _Chosen:
        """The chosen nodes of some rows, padded to their own largest count."""
        size = int(self.cnt[keep].max()) if np.any(keep) else 0
        return _Chosen(self.idx[keep, :size], self.t[keep, :size], self.cnt[keep])


def _moment_sums(prob: Problem, ch: _Chosen) -> tuple[FloatArray, BoolArray]:
    """Eq. 3 for every string, and whether it resists moments only one way (or none)."""
    p = prob.params
    sign = ch.t[..., _SIGN]
    n_ccw, n_cw = (sign > 0).sum(axis=1), (sign < 0).sum(axis=1)
    n = np.maximum(ch.cnt, 1).astype(float)
    f = ch.t[..., _ABSM].sum(axis=1) / (n if p.k == 1 else n**p.k)
    f /= np.abs(n_cw - n_ccw) + p.epsilon
    return f, (n_ccw == 0) | (n_cw == 0)


def _translation_ok(ch: _Chosen) -> BoolArray:
    """Push directions positively span the plane: the largest angular gap is below π."""
    size = ch.idx.shape[1]
    if size < 3:
        return np.zeros(len(ch.cnt), bool)
    a = ch.t[..., _ANGLE].copy()
    a.sort(axis=1)  # padding (10) sorts last
    inner = np.where(_STEPS[:, : size - 1] < ch.cnt[:, None] - 1, a[:, 1:] - a[:, :-1], -np.inf)
    last = a[np.arange(len(a)), np.maximum(ch.cnt - 1, 0)]
    wrap = a[:, 0] + 2 * np.pi - last
    return (ch.cnt >= 3) & (np.maximum(inner.max(axis=1), wrap) < np.pi - 1e-9)


def _shared_edge(ch: _Chosen) -> BoolArray:
    """Two robots on one edge."""
    if ch.idx.shape[1] < 2:
        return np.zeros(len(ch.cnt), bool)
    e = ch.t[..., _EDGE].copy()
    e.sort(axis=1)  # padding (−1) sorts first
    return ((e[:, 1:] == e[:, :-1]) & (e[:, 1:] >= 0)).any(axis=1)


@functools.lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs a < b of n items (cached: read only)."""
    a, b = np.triu_indices(n, 1)
    return a, b


def _pair_distances(ch: _Chosen) -> tuple[FloatArray, BoolArray]:
    """Squared distances between the chosen robot centres, pair by pair (P, n(n−1)/2), and
    which pairs are real (b < count: padding sorts last)."""
    a, b = _pairs(ch.idx.shape[1])
    dx = ch.t[:, a, _CX] - ch.t[:, b, _CX]
    dy = ch.t[:, a, _CY] - ch.t[:, b, _CY]
    return dx * dx + dy * dy, b[None] < ch.cnt[:, None]


def _too_close(prob: Problem, ch: _Chosen) -> BoolArray:
    d2, real = _pair_distances(ch)
    return (real & (d2 < (prob.min_gap - 1e-12) ** 2)).any(axis=1)


def _closest_pair(ch: _Chosen) -> FloatArray:
    """The least distance between two chosen robot centres (inf with fewer than two)."""
    d2, real = _pair_distances(ch)
    return np.sqrt(np.where(real, d2, np.inf).min(axis=1, initial=np.inf))


def _wrench_closure(prob: Problem, ch: _Chosen, tol: float = 1e-9) -> BoolArray:
    """First-order form closure: the chosen wrenches positively span R³. A set fails iff some
    closed half-space holds them all; its boundary plane can be taken through two of them (a set
    of rank ≤ 2 lies in such a plane; rank ≤ 1 fails translation closure before this check).
    Work and memory per string grow with n³ (n its robot count), not with K."""
    a, b = _pairs(ch.idx.shape[1])
    ia, ib = ch.idx[:, a], ch.idx[:, b]  # (P, m): the pairs
    w0, w1, w2 = prob.table[:, _W0], prob.table[:, _W1], prob.table[:, _W2]
    u0, u1, u2, v0, v1, v2 = w0[ia], w1[ia], w2[ia], w0[ib], w1[ib], w2[ib]
    y0, y1, y2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0  # pair plane normals
    plane = y0 * y0 + y1 * y1 + y2 * y2 > 1e-18
    side = (  # (P, m, n): every chosen wrench against every pair's plane (padding: 0)
        y0[..., None] * ch.t[:, None, :, _W0]
        + y1[..., None] * ch.t[:, None, :, _W1]
        + y2[..., None] * ch.t[:, None, :, _W2]
    )
    one_side = plane & ~((side < -tol).any(axis=-1) & (side > tol).any(axis=-1))
    return (ch.cnt >= 4) & ~one_side.any(axis=1)


def _closure_in_chunks(prob: Problem, ch: _Chosen) -> BoolArray:
    n = ch.idx.shape[1]
    step = max(1, CLOSURE_CHUNK // max(1, n * n * (n - 1) // 2))
    if step >= len(ch.cnt):
        return _wrench_closure(prob, ch)
    rows = [ch.rows(np.arange(len(ch.cnt)) // step == c) for c in range(-(-len(ch.cnt) // step))]
    return np.concatenate([_wrench_closure(prob, part) for part in rows])


def constraint_flags(prob: Problem, x: BoolArray) -> tuple[FloatArray, dict[str, BoolArray]]:
    """Eq. 3 for every string (P, K) (unpenalised) and which constraints each violates.

    ``closure`` (exact mode) is checked only on strings meeting every other constraint and
    counts as violated on the others (not shown to hold)."""
    p = prob.params
    ch = _Chosen.of(prob, np.asarray(x, bool))
    f, one_way = _moment_sums(prob, ch)
    none = np.zeros(len(ch.cnt), bool)
    flags = {
        "robots": ch.cnt < 3,
        "fleet": none if prob.max_robots is None else ch.cnt > prob.max_robots,
        "moments": one_way,
        "translation": ~_translation_ok(ch),
        "one_per_edge": _shared_edge(ch) if prob.one_per_edge else none,
        "spacing": _too_close(prob, ch),
    }
    if p.closure == "exact":
        rest = ~(flags["robots"] | flags["fleet"] | one_way | flags["translation"])
        rest &= ~(flags["one_per_edge"] | flags["spacing"])
        rest &= ch.cnt <= MAX_CLOSURE_SET
        closed = none.copy()
        if np.any(rest):
            closed[rest] = _closure_in_chunks(prob, ch.rows(rest))
        flags["closure"] = ~closed
    return f, flags


def evaluate(prob: Problem, x: BoolArray) -> tuple[FloatArray, NDArray[np.int64]]:
    """Objective of every string (P, K), the paper's penalty on infeasible ones, and its count
    of violated constraints (0: feasible)."""
    f, flags = constraint_flags(prob, x)
    viol = np.zeros(len(f), np.int64)
    for bad in flags.values():
        viol += bad
    return np.where(viol == 0, f, PENALTY), viol


def rank_strings(f: FloatArray, viol: NDArray[np.int64]) -> FloatArray:
    """Selection key: feasible strings by objective, infeasible ones below them by their count
    of violations (``-1e30 · v``: distinct in float64, unlike ``-1e30 - v``)."""
    return np.where(viol == 0, f, INFEASIBLE_RANK * viol)


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
    """``size`` strings of ``lo``..``hi`` robots at distinct random nodes."""
    order = rng.random((size, k)).argsort(axis=1)  # a random permutation per string
    count = np.minimum(rng.integers(lo, hi + 1, size), k)
    x = np.zeros((size, k), bool)
    x[np.arange(size)[:, None], order] = _STEPS[:, :k] < count[:, None]
    return x


def _mutate(x: np.ndarray, rows: list[int], rng: np.random.Generator) -> np.ndarray:
    """For each of ``rows``: move one robot 1–2 nodes along the boundary (70 %), jump it
    anywhere (10 %), add one (10 %) or remove one (10 %; never below three). Changes ``x`` in
    place and returns it (a loop: only a few children mutate)."""
    k = x.shape[1]
    for r in rows:
        on = x[r].nonzero()[0]
        u, v, w = rng.random(3).tolist()
        jump = int(w * 4 * k)
        pick = int(on[int(v * len(on))]) if len(on) else -1  # a random robot
        if u < 0.8 and pick >= 0:
            x[r, pick] = False
            x[r, (pick + _SHIFTS[jump % 4]) % k if u < 0.7 else jump // 4] = True
        elif u < 0.9 or len(on) <= 3:
            x[r, jump // 4] = True
        else:
            x[r, pick] = False
    return x


_SHIFTS = (-2, -1, 1, 2)


def _breed(
    pop: np.ndarray, key: FloatArray, n_child: int, p: CaptureParams, rng: np.random.Generator
) -> np.ndarray:
    """Children by size-2 tournaments on ``key``, two-point crossover (probability
    ``p.crossover``) and mutation (probability ``p.mutation`` per child)."""
    n, k = pop.shape
    u = rng.random((n_child, 8))  # 4 tournament entrants, 2 cuts, crossover and mutation coins
    t = (u[:, :4] * n).astype(np.int64)
    kt = key[t]
    pa = np.where(kt[:, 0] >= kt[:, 1], t[:, 0], t[:, 1])
    pb = np.where(kt[:, 2] >= kt[:, 3], t[:, 2], t[:, 3])
    cuts = (u[:, 4:6] * (k + 1)).astype(np.int64)
    cuts.sort(axis=1)
    cuts[u[:, 6] >= p.crossover] = 0  # no crossover: an empty segment
    cols = _STEPS[:, :k]
    seg = (cols >= cuts[:, :1]) & (cols < cuts[:, 1:])
    kids = np.where(seg, pop[pb], pop[pa])
    return _mutate(kids, (u[:, 7] < p.mutation).nonzero()[0].tolist(), rng)


def _moves(best: np.ndarray) -> NDArray[np.int64]:
    """Every one-move neighbour of a string as (node to clear, node to set) pairs: one robot
    relocated to any free node. O(n·K) pairs, materialised a batch at a time."""
    on = np.flatnonzero(best)
    off = np.flatnonzero(~best)
    return np.column_stack([np.repeat(on, len(off)), np.tile(off, len(on))])


def _apply_moves(best: np.ndarray, moves: NDArray[np.int64]) -> np.ndarray:
    out = np.repeat(best[None], len(moves), axis=0)
    r = np.arange(len(moves))
    out[r, moves[:, 0]] = False
    out[r, moves[:, 1]] = True
    return out


@dataclass
class GAResult:
    best: np.ndarray  # the best feasible string (all False when none was found)
    objective: float  # its objective (PENALTY when none was found)
    evaluations: int
    history: list[float] = field(default_factory=list)
    closest: np.ndarray | None = None  # the string with the fewest violations seen
    closest_violations: int = 0

    @property
    def found(self) -> bool:
        return self.objective > PENALTY


@dataclass
class _Search:
    """The GA's memory across generations: the best feasible and the closest strings seen,
    the current run's progress and the local-search queue of the elite's moves."""

    k: int
    best_x: np.ndarray | None = None
    best_f: float = -np.inf
    closest_x: np.ndarray | None = None
    closest_v: int = 1 << 30
    run_best: float = -np.inf
    since: int = 0
    queue: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    queue_of: bytes = b""

    def note(self, x: np.ndarray, f: FloatArray, v: NDArray[np.int64]) -> None:
        """Remember the best feasible and the least violating strings of a batch."""
        if len(v) == 0:
            return
        ok = np.where(v == 0, f, -np.inf)
        i = int(np.argmax(ok))
        if ok[i] > self.best_f:
            self.best_x, self.best_f = x[i].copy(), float(ok[i])
        j = int(np.argmin(v))
        if v[j] < self.closest_v:
            self.closest_x, self.closest_v = x[j].copy(), int(v[j])

    def progress(self, elite: np.ndarray, f: float, v: int, rng: np.random.Generator) -> None:
        """Count generations without a better feasible elite; queue a new elite's moves."""
        if v == 0 and f > self.run_best + 1e-12:
            self.run_best, self.since = f, 0
        else:
            self.since += 1
        if v == 0 and elite.tobytes() != self.queue_of:
            moves = _moves(elite)
            self.queue = moves[rng.permutation(len(moves))]
            self.queue_of = elite.tobytes()

    def converged(self, stall: int) -> bool:
        return self.since >= stall and len(self.queue) == 0

    def restart(self) -> None:
        self.run_best, self.since, self.queue_of = -np.inf, 0, b""

    def take(self, n: int) -> NDArray[np.int64]:
        out, self.queue = self.queue[:n], self.queue[n:]
        return out

    def result(self, evaluations: int, history: list[float]) -> GAResult:
        found = self.best_x is not None
        return GAResult(
            best=self.best_x if found else np.zeros(self.k, bool),
            objective=self.best_f if found else PENALTY,
            evaluations=evaluations,
            history=history,
            closest=self.closest_x,
            closest_violations=self.closest_v,
        )


Objective = Callable[[np.ndarray], tuple[FloatArray, NDArray[np.int64]]]
Rank = Callable[[FloatArray, NDArray[np.int64]], FloatArray]


def run_ga(
    prob: Problem,
    rng: np.random.Generator,
    objective: Objective | None = None,
    stall: int = 20,
    init: tuple[int, int] = (3, 6),
    rank: Rank = rank_strings,
) -> GAResult:
    """The GA on ``prob`` (objective ``evaluate`` unless another (f, viol) function is given;
    ``rank`` orders strings for selection and elitism).

    Within the budget (population × generations evaluations) a run that has converged (no
    better string for ``stall`` generations and its best string's neighbourhood searched)
    restarts from a fresh population; the best string ever found is the answer. Initial
    strings hold ``init`` robots, at most ``prob.max_robots``.
    """
    p = prob.params
    fn = objective or (lambda x: evaluate(prob, x))
    k = len(prob.cand.points)
    hi = min(init[1], prob.max_robots or init[1])
    lo = min(init[0], hi)
    pop = _initial(k, p.population, rng, lo, hi)
    f, v = fn(pop)
    search = _Search(k)
    search.note(pop, f, v)
    evals = len(pop)
    history: list[float] = []
    for _ in range(p.generations):
        key = rank(f, v)
        elite = int(np.argmax(key))
        search.progress(pop[elite], float(f[elite]), int(v[elite]), rng)
        if search.converged(stall):  # restart (the best ever is kept aside)
            search.restart()
            new = _initial(k, p.population, rng, lo, hi)
            pop, (f, v) = new, fn(new)
            fn_new, v_new = f, v
        else:  # the elite, a batch of its neighbours, children
            moves = search.take(p.population // 2)
            nxt = np.empty_like(pop)
            nxt[0] = pop[elite]
            nxt[1 : 1 + len(moves)] = _apply_moves(pop[elite], moves)
            nxt[1 + len(moves) :] = _breed(pop, key, p.population - 1 - len(moves), p, rng)
            new = nxt[1:]
            fn_new, v_new = fn(new)
            pop, f, v = (
                nxt,
                np.concatenate((f[elite : elite + 1], fn_new)),
                np.concatenate((v[elite : elite + 1], v_new)),
            )
        evals += len(new)
        search.note(new, fn_new, v_new)
        history.append(search.best_f if np.isfinite(search.best_f) else PENALTY)
    return search.result(evals, history)


def run_paper_ga(
    prob: Problem,
    rng: np.random.Generator,
    objective: Objective | None = None,
    init: tuple[int, int] = (3, 6),
) -> GAResult:
    """Sharma et al.'s GA as published, the baseline for :func:`run_ga`: binary strings, the
    penalty −1e20 on every infeasible string (no ranking among them), population
    ``population`` (60), crossover fraction ``crossover`` (0.8), mutation ``mutation`` (0.12)
    and ``population × generations`` evaluations (36 000), with the operators of the MATLAB
    ``ga`` the paper ran (its defaults for bit strings): rank fitness scaling (1/√rank),
    stochastic uniform selection, ``ceil(0.05 · population)`` elites, scattered (uniform)
    crossover for that fraction of the other children, and for the rest a parent with every
    bit flipped with probability ``mutation`` (mutation only on children not made by
    crossover). No local search, no restarts. One deviation, stated: initial strings hold 3-6
    robots like ours (a uniform random start, half the bits set, never reaches a feasible set).
    ``objective`` and ``init`` as for :func:`run_ga` (Eq. 5's pushers: exactly n robots).
    """
    p = prob.params
    fn = objective or (lambda x: evaluate(prob, x))
    k = len(prob.cand.points)
    hi = min(init[1], prob.max_robots or init[1])
    lo = min(init[0], hi)
    n = p.population
    n_elite = min(int(np.ceil(0.05 * n)), n)
    n_cross = int(round(p.crossover * (n - n_elite)))
    pop = _initial(k, n, rng, lo, hi)
    f, v = fn(pop)
    search = _Search(k)
    search.note(pop, f, v)
    evals = n
    history: list[float] = []
    ranks = np.arange(1, n + 1)
    scaled = 1.0 / np.sqrt(ranks)
    while evals + n - n_elite <= n * p.generations:  # the budget: 36 000 at 60 × 600
        order = np.argsort(-f, kind="stable")  # infeasible strings all tie at the penalty
        expect = np.empty(n)
        expect[order] = scaled * n / scaled.sum()
        # stochastic uniform selection: one spin, equally spaced pointers
        n_par = 2 * n_cross + (n - n_elite - n_cross)
        step = n / n_par
        ptr = rng.random() * step + step * np.arange(n_par)
        parents = np.searchsorted(np.cumsum(expect), ptr, side="right").clip(0, n - 1)
        parents = parents[rng.permutation(n_par)]
        elite = pop[order[:n_elite]]
        a, b = pop[parents[:n_cross]], pop[parents[n_cross : 2 * n_cross]]
        cross = np.where(rng.random((n_cross, k)) < 0.5, a, b)
        mut = pop[parents[2 * n_cross :]] ^ (rng.random((n - n_elite - n_cross, k)) < p.mutation)
        new = np.vstack([cross, mut])
        f_new, vn = fn(new)
        evals += len(new)
        search.note(new, f_new, vn)
        pop = np.vstack([elite, new])
        f = np.concatenate([f[order[:n_elite]], f_new])
        history.append(search.best_f if np.isfinite(search.best_f) else PENALTY)
    return search.result(evals, history)


def ga_of(params: CaptureParams) -> Callable[[Problem, np.random.Generator], GAResult]:
    """The GA ``capture.ga`` names: "ours" (:func:`run_ga`) or "paper" (:func:`run_paper_ga`)."""
    return run_paper_ga if params.ga == "paper" else run_ga


# --------------------------------------------------------------------------- results


@dataclass
class CapturePlan:
    candidates: FloatArray
    normals: FloatArray
    edges: NDArray[np.int64]
    chosen: NDArray[np.int64]
    points: FloatArray  # (M, 2) object frame (empty when infeasible)
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
    feasible: bool = False  # zero violations and (exact mode) the LP certificate
    reason: str = ""  # why not feasible: the constraint that could not be met
    violated: list[str] = field(default_factory=list)  # machine-readable: CONSTRAINTS, ...
    max_robots: int | None = None  # the fleet size the plan was limited to

    def to_json(self) -> dict[str, Any]:
        return {
            "feasible": self.feasible,
            "reason": self.reason,
            "violated": list(self.violated),
            "max_robots": self.max_robots,
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

    def text(self) -> str:
        """A few lines for a person: the outcome, then one line per capture point."""
        if not self.feasible:
            return f"capture: infeasible: {self.reason}"
        lines = [
            f"capture: {self.robots_needed} robots, objective {self.objective:.4g}, "
            f"N_cw {self.N_cw} N_ccw {self.N_ccw}, form closure {self.form_closure}, "
            f"{self.evaluations} evaluations"
        ]
        lines += [
            f"  point ({p[0]:.3f}, {p[1]:.3f}) normal ({n[0]:.2f}, {n[1]:.2f})"
            for p, n in zip(self.points, self.push_normals, strict=True)
        ]
        return "\n".join(lines)

    @classmethod
    def refused(
        cls, params: CaptureParams, reason: str, violated: list[str], max_robots: int | None
    ) -> CapturePlan:
        """An infeasible plan with no candidates (the problem could not be built)."""
        none2, none = np.zeros((0, 2)), np.zeros(0, np.int64)
        return cls(none2, none2, none, none, none2, none2, 0, PENALTY, 0.0, 0.0, 0, 0, False,
                   False, 0, [], params.closure, feasible=False, reason=reason,
                   violated=violated, max_robots=max_robots)  # fmt: skip


def describe(
    prob: Problem,
    bits: np.ndarray,
    evaluations: int,
    history: list[float],
    reason: str = "",
    violated: list[str] | None = None,
) -> CapturePlan:
    """The plan for a chosen string, with the paper's check and the exact certificate.
    Feasible iff the string has zero violations and, in exact mode, the LP certificate;
    ``reason`` and ``violated`` explain an infeasible one (the string is then not used)."""
    f, v = evaluate(prob, bits[None])
    paper = CaptureParams(**{**prob.params.__dict__, "closure": "paper"})
    _, v_paper = evaluate(Problem(**{**prob.__dict__, "params": paper}), bits[None])
    chosen = np.flatnonzero(bits)
    pts, nrm = prob.cand.points[chosen], prob.cand.normals[chosen]
    certified = certify_form_closure(pts, nrm, prob.centroid)
    feasible = bool(len(chosen) > 0 and v[0] == 0 and (certified or prob.params.closure == "paper"))
    if not feasible and not reason and len(chosen):
        reason, violated = "the LP certificate rejects the GA's closure test", ["closure"]
    if not feasible:
        chosen, pts, nrm = chosen[:0], pts[:0], nrm[:0]
    m = prob.moments[chosen]
    tau = prob.params.tau
    return CapturePlan(
        candidates=prob.cand.points,
        normals=prob.cand.normals,
        edges=prob.cand.edges,
        chosen=chosen,
        points=pts,
        push_normals=nrm,
        robots_needed=len(chosen),
        objective=float(f[0]) if feasible else PENALTY,
        M_cw=float(m[m < -tau].sum()),
        M_ccw=float(m[m > tau].sum()),
        N_cw=int((m < -tau).sum()),
        N_ccw=int((m > tau).sum()),
        paper_feasible=bool(feasible and v_paper[0] == 0),
        form_closure=bool(feasible and certified),
        evaluations=evaluations,
        history=history,
        closure=prob.params.closure,
        note=prob.n_robots_note,
        feasible=feasible,
        reason="" if feasible else reason,
        violated=[] if feasible else list(violated or []),
        max_robots=prob.max_robots,
    )


# --------------------------------------------------------------------------- why infeasible


def _need(p: CaptureParams) -> str:
    if p.closure == "exact":
        return "first-order form closure needs 4 robots at least (frictionless contacts)"
    return "the paper's closure needs 3 robots at least"


def packing_bound(prob: Problem) -> int:
    """An upper bound on how many robots fit around the object at once (centres at least
    ``min_gap`` apart): the candidates, in boundary order, split into runs whose centres are all
    pairwise too close (one robot per run at most); the last run joins the first if it can."""
    c, gap = prob.centres, prob.min_gap - 1e-12
    runs: list[tuple[int, int]] = []
    start = 0
    while start < len(c):
        end = start + 1
        while end < len(c) and np.all(np.hypot(*(c[start:end] - c[end]).T) < gap):
            end += 1
        runs.append((start, end))
        start = end
    if len(runs) > 1:
        ends = np.vstack([c[slice(*runs[0])], c[slice(*runs[-1])]])
        d = np.hypot(*(ends[:, None] - ends[None]).transpose(2, 0, 1))
        if np.all(d[~np.eye(len(ends), dtype=bool)] < gap):
            return len(runs) - 1
    return len(runs)


def structural_reason(prob: Problem) -> tuple[str, list[str]]:
    """Why no plan can exist, found without search (or "" when the GA must look)."""
    p, cand, r = prob.params, prob.cand, prob.robot_radius
    need, why, k = p.min_robots, _need(prob.params), len(prob.cand.points)
    if k < need and cand.total >= need:
        return (
            f"robots too large for the object: a robot of radius {r:g} m fits at only {k} of "
            f"the {cand.total} candidate nodes (capture.spacing {p.spacing:g} m); {why}",
            ["robots"],
        )
    if k < need:
        return (
            f"too few candidate nodes: capture.spacing {p.spacing:g} m gives {k} on this object; "
            f"{why}: use a finer capture.spacing",
            ["robots"],
        )
    if prob.max_robots is not None and prob.max_robots < need:
        return f"closure impossible with the fleet: {why}; the fleet has {prob.max_robots}", [
            "fleet"
        ]
    edges = len(np.unique(cand.edges))
    if prob.one_per_edge and edges < need:
        return (
            f"one robot per edge: only {edges} edges have room for a robot of radius {r:g} m; "
            f"{why}",
            ["one_per_edge"],
        )
    fit = packing_bound(prob)
    if fit < need:
        return (
            f"robots too large for the object: at most {fit} robots of radius {r:g} m fit around "
            f"it with centres {prob.min_gap:.3g} m (2·radius + clearance) apart; {why}",
            ["spacing"],
        )
    return "", []


def _closest_reason(prob: Problem, res: GAResult) -> tuple[str, list[str]]:
    """What the least violating string the GA saw gets wrong."""
    head = f"the GA found no feasible capture in {res.evaluations} evaluations"
    if res.closest is None:
        return head, []
    x = res.closest[None]
    _, flags = constraint_flags(prob, x)
    bad = [name for name in CONSTRAINTS if name in flags and flags[name][0]]
    if "closure" in bad and len(bad) > 1:
        bad.remove("closure")  # closure is only checked once the others hold
    n = int(x.sum())
    gap = float(_closest_pair(_Chosen.of(prob, x))[0])
    detail = {
        "robots": f"{n} robots, at least 3 needed",
        "fleet": f"{n} robots, the fleet has {prob.max_robots}",
        "moments": "clockwise and counter-clockwise moments are not both resisted",
        "translation": "the push directions leave a half-plane free (translation closure)",
        "one_per_edge": "two robots on one edge",
        "spacing": f"robot centres {gap:.3g} m apart where {prob.min_gap:.3g} m "
        "(2·radius + clearance) is needed",
        "closure": "the wrenches do not positively span R³ (first-order form closure)",
    }
    text = "; ".join(f"{b}: {detail[b]}" for b in bad)
    return f"{head}; the closest plan ({n} robots) violates {text}", bad


def _retry_without_fleet(prob: Problem, rng: np.random.Generator) -> tuple[str, GAResult | None]:
    """The GA once more without the fleet limit: a capture that needs more robots than the
    fleet has gives the reason; one within the fleet after all is returned."""
    if prob.max_robots is None or prob.max_robots >= len(prob.cand.points):
        return "", None
    res = ga_of(prob.params)(Problem(**{**prob.__dict__, "max_robots": None}), rng)
    if not res.found:
        return "", None
    m = int(res.best.sum())
    if m > prob.max_robots:
        return (
            f"closure impossible with the fleet: the best capture found needs {m} robots; "
            f"the fleet has {prob.max_robots}",
            None,
        )
    return "", res


def plan_capture(
    polygon: FloatArray,
    robot_radius: float,
    params: CaptureParams,
    rng: np.random.Generator,
    max_robots: int | None = None,
) -> CapturePlan:
    """Capture points for a polygon (object frame) by the GA, with at most ``max_robots``
    robots (the fleet size; None: no limit). Always a plan: check ``feasible`` and ``reason``."""
    poly = geometry.ensure_ccw(polygon)
    budget = capture_budget_error(poly, params.spacing)
    if budget:
        return CapturePlan.refused(params, f"capture.spacing: {budget}", ["budget"], max_robots)
    prob = make_problem(poly, robot_radius, params, max_robots=max_robots)
    reason, violated = structural_reason(prob)
    if reason:
        return describe(prob, np.zeros(len(prob.cand.points), bool), 0, [], reason, violated)
    res = ga_of(params)(prob, rng)
    if not res.found:
        reason, retry = _retry_without_fleet(prob, rng)
        violated = ["fleet"] if reason else []
        if retry is not None:
            res = GAResult(retry.best, retry.objective, res.evaluations + retry.evaluations,
                           retry.history)  # fmt: skip
        elif not reason:
            reason, violated = _closest_reason(prob, res)
    return describe(prob, res.best, res.evaluations, res.history, reason, violated)


def plan_for_fleet(
    cfg: Any, rng: np.random.Generator | None = None, max_robots: int | None = None
) -> CapturePlan:
    """The capture plan for a config: its object, the fleet's largest robot radius, at most as
    many robots as the fleet has (or ``max_robots``: the robots left after some were lost),
    the ``[capture]`` parameters (``rng`` from capture.seed).

    The robots' spacing uses the larger of ``capture.clearance`` and ``approach.safety_margin``:
    the approach's safety filter keeps robot centres ``r_i + r_j + safety_margin`` apart, so
    points closer than that could never all be reached."""
    params = CaptureParams.from_config(cfg.capture)
    clearance = max(params.clearance, cfg.approach.safety_margin)
    return plan_capture(
        cfg.object_polygon(),
        cfg.max_robot_radius,
        dataclasses.replace(params, clearance=clearance),
        rng if rng is not None else np.random.default_rng(cfg.capture.seed),
        max_robots=len(cfg.robots) if max_robots is None else max_robots,
    )


# --------------------------------------------------------------------------- Eq. 5 and assignment


def push_objective(
    prob: Problem, direction: FloatArray, n: int, x: NDArray[np.bool_]
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Eq. 5: D·ΣF_i over strings of exactly n nodes, spacing kept, D inside the cone of the
    chosen push directions."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    f_push = -prob.cand.normals
    ch = _Chosen.of(prob, x)
    mask = ch.mask
    proj = f_push[:, 0] * d[0] + f_push[:, 1] * d[1]  # (no BLAS call in the loop)
    val = np.where(mask, proj[np.minimum(ch.idx, len(proj) - 1)], 0.0).sum(axis=1)
    viol = (ch.cnt != n).astype(np.int64)
    viol += _too_close(prob, ch)
    # D in cone(F): some chosen F on each side of D (or along it) within a half-turn
    psi = np.arctan2(f_push[:, 0] * d[1] - f_push[:, 1] * d[0], proj)  # angle F → D
    psi = np.where(mask, psi[np.minimum(ch.idx, len(psi) - 1)], np.nan)
    along = np.any(np.abs(psi) < 1e-9, axis=1)
    left = np.where(psi > 0, psi, np.inf).min(axis=1, initial=np.inf)
    right = np.where(psi < 0, -psi, np.inf).min(axis=1, initial=np.inf)
    viol += ~(along | (left + right <= np.pi))
    return np.where(viol == 0, val, PENALTY), viol


def plan_push_arrangement(
    polygon: FloatArray,
    robot_radius: float,
    direction: FloatArray,
    n: int,
    params: CaptureParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, float]:
    """Eq. 5 by the GA ``capture.ga`` names (ours, or the paper's as published): the n nodes
    (indices into the candidates) pushing hardest along D."""
    prob = make_problem(polygon, robot_radius, params)

    def fn(x: np.ndarray):
        return push_objective(prob, direction, n, x)

    ga = run_paper_ga if params.ga == "paper" else run_ga
    res = ga(prob, rng, objective=fn, init=(n, n))  # strings start with exactly n robots
    return np.flatnonzero(res.best), res.objective


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
