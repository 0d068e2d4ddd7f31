"""Global route planning for the carried object (Yamashita et al. §3), and the shared A* core.

Pure: arrays and frozen dataclasses in, a :class:`RouteResult` out; no I/O, no clock.

**Use.** Build the C-space once per config (:func:`controller.planning.cspace.build_object_cspace`),
a :class:`RoutePlanner` once per goal, then ``planner.plan(start_pose)`` for every (re-)plan::

    cs = build_object_cspace(bounds, obstacles, polygon, robot_radius, res, heading_bins)
    planner = RoutePlanner(cs, goal_pose, cfg.route)        # checks the goal, builds tables
    route = planner.plan(object_pose)                       # cheap; call again to re-plan

:func:`plan_route` does all three in one call. Poses are object-frame poses (x m, y m, theta
rad) as ``object.start``/``object.goal``.

**The search** runs over the lattice of :mod:`controller.planning.cspace` (the reference point
at cell centres, K headings) with

    f(n') = max(f(n), w_g g(n') + w_h h(n'))        (Eq. 1 with the pathmax of Eq. 2)

``w_g`` is 0 or 1, ``w_h >= 0``; ``w_h = 0`` is Dijkstra, ``w_g = 0`` greedy best-first. Costs
are seconds: distance / ``speed``, rotation / ``yaw_rate``, plus ``manipulation_cost`` whenever
the kind of move changes (a new translation direction, or switching between translating and
turning: the robots around the object re-arrange; Yamashita puts the manipulation constraints
into the cost function). The search state is (cell, heading, kind of the last move), 11 modes
per lattice state, so that cost is exact.

**Exact start and goal.** The start pose joins the lattice by one turn in place to one of the
two nearest heading bins and one straight move to the centre of its cell or a neighbour (or the
move first, then the turn, where that is free); the goal is reached the same way backwards,
ending with the final turn to the goal heading. Every one of these moves, and every lattice
move, is checked exactly against the grown footprint
(:class:`controller.planning.cspace.FootprintChecker`) and costed like any other move, its
changes of kind charged too; the first and last waypoints are the exact start and goal.
Waypoints are one straight move or one turn of at most ``min(2 pi / K, pi / 4)`` apart.

**Heuristics** (s): (D) ``cost_to_go``, the default: the lattice's cost-to-go to the goal's ways
with the manipulation cost (:func:`controller.planning.heuristics.lattice_cost_to_go`), computed
once per planner, refined per mode along the ray of the last move (:class:`_CostToGoH`):
admissible, and with the default parameters exact or nearly so, so that the search expands
little more than the route itself. The paper's potentials (A) ``euclid``, (B) ``wavefront``,
(C) ``skeleton``: a distance table over the (x, y) cells free at some heading, divided by
``speed``, plus the smallest heading change to the goal divided by ``yaw_rate``, plus
``manipulation_cost`` times the fewest changes of travel direction still needed
(:func:`controller.planning.heuristics.turn_bounds`). ``turn_bound=False`` leaves the
manipulation out of every heuristic (the paper's bare potentials). Translation + rotation, and
manipulation, are separate cost terms, so the sum of a lower bound of each is a lower bound:
(A), (B), (D) are admissible and ``w_g = w_h = 1`` returns the optimal cost on the lattice; (C)
is not. Re-opening of closed states: always for A* (``w_g = 1``, ``w_h <= 1``), never for
greedy, for ``w_h > 1`` when ``route.reopen`` is set.

Unreachable goals are answers, not errors: ``status = "no_path"`` with a reason.

**Speed.** :meth:`RoutePlanner.plan` runs a search loop specialised to these states
(``_FastSearch``): each lattice cell's checked moves are found once per planner (not once per
expansion of each of its modes), h is read once per state, tables through memoryviews. It is
the generic :func:`weighted_astar` over ``_ObjectMoves`` step for step (same f, pathmax,
tie-breaking, re-opening and pruning, so the same expansions and route);
``plan(..., reference=True)`` runs that reference (``tests/unit/test_route_speed.py`` compares
them, ``bench/route_speed.py`` times them against the code of before).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller import geometry
from controller.config import HEURISTICS, FleetConfig, RouteSection
from controller.planning import heuristics
from controller.planning.cspace import (
    MOVES_8,
    TURN_DOWN,
    TURN_UP,
    ObjectCSpace,
    build_object_cspace,
)

if TYPE_CHECKING:
    from controller.planning.pushability import PushDirections

FloatArray = NDArray[np.float64]
INF = math.inf

#: Modes of the object search (the kind of the last move): 0-7 the translation directions of
#: ``MOVES_8``, turning, the start (any first move is free), and a move joining an exact start or
#: goal in a direction off the lattice's eight.
MODE_ROTATE = 8
MODE_START = 9
MODE_JOIN = 10
N_MODES = 11


@dataclass(frozen=True, eq=False)
class RouteResult:
    """A planned route, or why there is none.

    status: "ok" or "no_path"; reason: empty when ok, else why (human readable).
    waypoints: (k, 3) object-frame poses (m, m, rad); consecutive waypoints differ by one
    straight move or one turn in place (never both); the first and last are the exact start and
    goal. subgoals: (m, 3) poses where the travel direction or the kind of move changes (the
    robots re-arrange there), long straight runs cut every ``subgoal_spacing`` m, ending with the
    goal. cost: seconds (inf when no path); length_m: distance (m) travelled by straight moves
    (turns in place add none); rotation_rad: total turning; manipulations: number of
    re-arrangements paid for; expanded: nodes expanded (N_open); generated: nodes pushed on the
    open list; reexpanded: expansions of an already expanded node; f_trace: f of each expansion
    (only when asked for); too_heavy: no route exists along which the fleet can push the object
    (the reason says the force needed and the best any set reaches), though one exists for the
    object alone; push_limited: the route keeps to the ways the fleet can push (a heavy object:
    the route without that limit asked for a push no set of the fleet makes).
    """

    status: str
    reason: str = ""
    waypoints: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    subgoals: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    cost: float = INF
    length_m: float = 0.0
    rotation_rad: float = 0.0
    manipulations: int = 0
    expanded: int = 0
    generated: int = 0
    reexpanded: int = 0
    heuristic: str = ""
    wg: float = 1.0
    wh: float = 1.0
    f_trace: FloatArray = field(default_factory=lambda: np.zeros(0))
    too_heavy: bool = False
    push_limited: bool = False

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def lateral_deviation(self, xy: ArrayLike) -> float:
        """Distance (m) from a point to the route's (x, y) polyline (inf when there is none)."""
        wp = self.waypoints
        if len(wp) == 0:
            return INF
        p = np.asarray(xy, dtype=float)[:2]
        if len(wp) == 1:
            return float(np.linalg.norm(p - wp[0, :2]))
        d, _ = geometry.point_segment_distance(p[None], wp[:-1, :2], wp[1:, :2])
        return float(d.min())

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (inf cost becomes None)."""
        return {
            "status": self.status,
            "reason": self.reason,
            "waypoints": self.waypoints.tolist(),
            "subgoals": self.subgoals.tolist(),
            "cost": self.cost if math.isfinite(self.cost) else None,
            "length_m": self.length_m,
            "rotation_rad": self.rotation_rad,
            "manipulations": self.manipulations,
            "expanded": self.expanded,
            "generated": self.generated,
            "reexpanded": self.reexpanded,
            "heuristic": self.heuristic,
            "wg": self.wg,
            "wh": self.wh,
            "too_heavy": self.too_heavy,
            "push_limited": self.push_limited,
        }


def _no_path(reason: str, heuristic: str, wg: float, wh: float, **kw: Any) -> RouteResult:
    return RouteResult(status="no_path", reason=reason, heuristic=heuristic, wg=wg, wh=wh, **kw)


def _check_weights(wg: float, wh: float) -> None:
    if wg not in (0.0, 1.0):
        raise ValueError(f"wg: expected 0 or 1, got {wg!r}")
    if not (wh >= 0 and math.isfinite(wh)):
        raise ValueError(f"wh: expected a finite number >= 0, got {wh!r}")


def reopens(wg: float, wh: float, reopen: bool) -> bool:
    """Whether the search re-opens closed states: always for A* (w_g = 1, w_h <= 1, so the cost
    stays optimal with an inconsistent heuristic), never for greedy (w_g = 0: g does not order
    the search), and for w_h > 1 when asked (``route.reopen``)."""
    if wg == 0.0:
        return False
    return wh <= 1.0 or reopen


# --------------------------------------------------------------------------- the A* core


@dataclass(frozen=True, eq=False)
class SearchOutcome:
    """What :func:`weighted_astar` found: the states of the path (or None), its cost and counts."""

    path: list[int] | None
    cost: float
    expanded: int
    generated: int
    reexpanded: int
    f_trace: list[float]
    limited: bool

    def counts(self) -> dict[str, Any]:
        """The search counts as :class:`RouteResult` fields."""
        return {
            "expanded": self.expanded,
            "generated": self.generated,
            "reexpanded": self.reexpanded,
            "f_trace": np.asarray(self.f_trace, dtype=float),
        }

    def reason(self, max_expanded: int) -> str:
        """Why the search found no path."""
        if self.limited:
            return f"expansion limit of {max_expanded} nodes reached"
        return "search exhausted: goal unreachable"


class InfDict(dict):
    """A dict of g values that reads inf for a state never reached."""

    def __missing__(self, key: int) -> float:
        return INF


class FalseDict(dict):
    """A dict of flags that reads False for a state never marked."""

    def __missing__(self, key: int) -> bool:
        return False


def _unwind(parent: Any, s: int) -> list[int]:
    path = [s]
    while parent[path[-1]] >= 0:
        path.append(parent[path[-1]])
    return path[::-1]


def weighted_astar(
    start: int,
    goal: int,
    h: Sequence[float],
    moves_of: Callable[[int, float], Iterable[tuple[int, float]]] | Sequence[tuple[int, float]],
    *,
    wg: float,
    wh: float,
    n_states: int = 0,
    pathmax: bool = True,
    reopen: bool = True,
    max_expanded: int = 20_000_000,
    trace: bool = False,
) -> SearchOutcome:
    """Weighted A* with pathmax (Eq. 1-2): the one search loop of the object and robot routes.

    States are ints. ``moves_of(s, g)`` yields the moves out of ``s`` (reached at cost ``g``) as
    (offset, cost): the successor is ``s + offset``; a plain sequence of moves is the same for
    every state (a grid). ``h[t]`` (s) is the heuristic; inf marks a state that may not be
    entered. ``n_states``: when > 0 the states are ``0 .. n_states - 1`` and the tables are flat
    lists (fast), else dicts. Ties in f go to the smaller h. ``reopen``: whether a closed state
    reached at a lower g is expanded again (see :func:`reopens`).
    """
    if n_states > 0:
        gbest: Any = [INF] * n_states
        parent: Any = [-1] * n_states
        closed: Any = bytearray(n_states)
    else:
        gbest, parent, closed = InfDict(), {}, FalseDict()
    fixed = not callable(moves_of)
    parent[start] = -1
    gbest[start] = 0.0
    h0 = h[start]
    heap: list[tuple[float, float, float, int]] = [(wh * h0, h0, 0.0, start)]
    push, pop, inf = heapq.heappush, heapq.heappop, INF
    ftrace: list[float] = []
    expanded = reexpanded = 0
    generated = 1
    while heap:
        f, _, g, s = pop(heap)
        if g > gbest[s]:
            continue
        if closed[s]:
            reexpanded += 1
        closed[s] = 1
        expanded += 1
        if trace:
            ftrace.append(f)
        if s == goal:
            return SearchOutcome(
                _unwind(parent, s), g, expanded, generated, reexpanded, ftrace, False
            )
        if expanded >= max_expanded:
            return SearchOutcome(None, inf, expanded, generated, reexpanded, ftrace, True)
        for off, cost in moves_of if fixed else moves_of(s, g):  # type: ignore[operator]
            t = s + off
            h2 = h[t]
            if h2 < inf:
                g2 = g + cost
                if g2 < gbest[t] and (reopen or not closed[t]):
                    gbest[t] = g2
                    parent[t] = s
                    f2 = wg * g2 + wh * h2
                    if pathmax and f2 < f:
                        f2 = f
                    push(heap, (f2, h2, g2, t))
                    generated += 1
    return SearchOutcome(None, INF, expanded, generated, reexpanded, ftrace, False)


# --------------------------------------------------------------------------- post-processing


def _subgoal_indices(xy: FloatArray, modes: Sequence[Any], spacing: float) -> list[int]:
    """Indices of the waypoints that become subgoals: mode changes, spacing cuts, the goal.

    ``modes[i]`` is the kind of the move that ends at waypoint i (``modes[0]`` is unused).
    """
    n = len(xy)
    if n == 0:
        return []
    turns = [i for i in range(1, n - 1) if modes[i + 1] != modes[i]]
    keys = [0] + turns + [n - 1]
    seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    out: list[int] = []
    for a, b in zip(keys[:-1], keys[1:], strict=True):
        run = seg[b] - seg[a]
        if run > spacing:
            pieces = int(math.ceil(run / spacing - 1e-9))
            for j in range(1, pieces):
                out.append(int(np.searchsorted(seg, seg[a] + j * run / pieces)))
        out.append(b)
    return sorted(set(out))


def ok_result(
    wp: FloatArray,
    kinds: Sequence[Any],
    spacing: float,
    cost: float,
    length: float,
    manipulations: int,
    search: tuple[str, float, float],
    counts: dict[str, Any],
) -> RouteResult:
    """A found route: waypoints (k, 3), the kind of each move (for the subgoals), the subgoal
    spacing (m), cost (s), length (m), re-arrangements, (heuristic, wg, wh), search counts."""
    idx = _subgoal_indices(wp[:, :2], kinds, spacing)
    _, turn = _lengths(wp)
    kind, wg, wh = search
    return RouteResult(
        status="ok",
        waypoints=wp,
        subgoals=wp[idx],
        cost=float(cost),
        length_m=length,
        rotation_rad=turn,
        manipulations=manipulations,
        heuristic=kind,
        wg=float(wg),
        wh=float(wh),
        **counts,
    )


def _lengths(wp: FloatArray) -> tuple[float, float]:
    if len(wp) < 2:
        return 0.0, 0.0
    length = float(np.sum(np.linalg.norm(np.diff(wp[:, :2], axis=0), axis=1)))
    turn = float(np.sum(np.abs(geometry.wrap_angle(np.diff(wp[:, 2])))))
    return length, turn


def _move_kinds(ref: FloatArray) -> list[Any]:
    """Kind of each move between reference poses: "turn" or the rounded travel direction."""
    kinds: list[Any] = [None]
    for a, b in zip(ref[:-1], ref[1:], strict=True):
        d = b[:2] - a[:2]
        n = float(np.hypot(*d))
        if n < 1e-9:
            kinds.append("turn")
        else:
            kinds.append((round(float(d[0]) / n, 6), round(float(d[1]) / n, 6)))
    return kinds


def _split_turn(a: FloatArray, dtheta: float, max_step: float) -> list[FloatArray]:
    """Poses after a turn in place from ``a`` by ``dtheta``, in pieces no larger than max_step
    (so the direction of every piece is unambiguous)."""
    n = max(1, int(math.ceil(abs(dtheta) / max_step - 1e-9)))
    return [np.array([a[0], a[1], a[2] + dtheta * (i + 1) / n]) for i in range(n)]


# --------------------------------------------------------------------------- the planner


@dataclass(frozen=True)
class _Join:
    """A way between an exact pose and a lattice state (a start or goal connector)."""

    state: int  # padded flat lattice index
    cost: float  # s, without manipulation charges
    seq: list[FloatArray]  # reference poses strictly between the exact pose and the state
    modes: tuple[int, ...]  # modes of its pieces in the order travelled (empty: no move at all)
    push_angle: float | None = None  # its straight piece's direction in the object's frame (rad)

    @property
    def changes(self) -> int:
        """Changes of the kind of move between its own pieces."""
        return sum(1 for a, b in zip(self.modes[:-1], self.modes[1:], strict=True) if a != b)


def _step_mode(v: FloatArray) -> int:
    """The mode of a straight move by v: a lattice direction if v is along one, else a join."""
    for d, (dx, dy) in enumerate(MOVES_8):
        if abs(v[0] * dy - v[1] * dx) < 1e-12 and v[0] * dx + v[1] * dy > 0:
            return d
    return MODE_JOIN


class _PotentialH:
    """h (s) of object search states for the paper's potentials: a (x, y, theta) table plus the
    per-mode manipulation bound; 0 for the virtual start and goal."""

    def __init__(self, h3: FloatArray, hmode: list[FloatArray], layer: int, n_lattice: int):
        self.h3 = h3
        self.hmode = hmode
        self.layer = layer
        self.n = n_lattice * N_MODES

    def __getitem__(self, s: int) -> float:
        if s >= self.n:
            return 0.0
        c, m = divmod(s, N_MODES)
        v = float(self.h3[c])
        if v == INF:
            return INF
        return v + float(self.hmode[m][c % self.layer])


def _arrival_charge(mode: int, first: int) -> bool:
    """Whether arriving in ``mode`` at a way that begins with ``first`` is a change of kind."""
    if mode == MODE_START or first < 0:
        return False
    return mode != first or first == MODE_JOIN


class _CostToGoH:
    """h (s) of object search states from the lattice cost-to-go E (the first move's kind free;
    padded flat) and the goal's ways (per lattice state: cost with their own changes, first kind).

    For a state that last moved in mode m the cost-to-go is ``D_m(c) = min(join_m(c),
    manip + E(c), cost of one more move in mode m + D_m(next))``: walked along the ray of mode m
    (a translation direction, or turning either way) on first use and memoised; a lower bound
    because E is. The start mode takes the smaller of E and its join; a join move (off the
    lattice's directions) has no free continuation.
    """

    def __init__(
        self,
        planner: RoutePlanner,
        e: FloatArray,
        joins: dict[int, list[tuple[float, int]]],
        manip: float,
    ):
        self.e, self.joins, self.manip = e, joins, manip
        self.n = planner._n * N_MODES
        self.toff, self.tcost, self.rc = planner._toff, planner._tcost, planner._rot_cost
        self.layer, self.k_bins = planner._layer, planner.cspace.heading_bins
        self.memo: dict[int, float] = {}

    def join(self, c: int, mode: int) -> float:
        """Cost of joining the goal from lattice state c arrived at in ``mode`` (inf if none)."""
        ways = self.joins.get(c)
        if ways is None:
            return INF
        return min(b + self.manip * _arrival_charge(mode, f) for b, f in ways)

    def _step(self, c: int, ray: int) -> int:
        if ray < 8:
            return c + self.toff[ray]
        k = c // self.layer
        if ray == TURN_UP:
            return c - (self.k_bins - 1) * self.layer if k == self.k_bins - 1 else c + self.layer
        return c + (self.k_bins - 1) * self.layer if k == 0 else c - self.layer

    def _ray(self, c: int, ray: int) -> float:
        """D along a ray (translation direction 0-7, TURN_UP, TURN_DOWN) from state c."""
        memo, e = self.memo, self.e
        cost = self.tcost[ray] if ray < 8 else self.rc
        mode = ray if ray < 8 else MODE_ROTATE
        path = []
        x, val = c, INF
        for _ in range(self.n):
            v = memo.get(x * 10 + ray)
            if v is not None:
                val = v
                break
            if float(e[x]) == INF:
                break
            path.append(x)
            x = self._step(x, ray)
            if x == c:  # turned full circle
                break
        for x in reversed(path):
            val = min(self.join(x, mode), self.manip + float(e[x]), cost + val)
            memo[x * 10 + ray] = val
        return val

    def __getitem__(self, s: int) -> float:
        if s >= self.n:
            return 0.0
        c, m = divmod(s, N_MODES)
        e = float(self.e[c])
        if e == INF or self.manip <= 0:
            return e
        if m == MODE_START:
            return min(e, self.join(c, m))
        if m < 8:
            return max(e, self._ray(c, m))
        v = min(self.join(c, m), self.manip + e)
        if m == MODE_ROTATE and self.k_bins > 1:
            up = self._ray(self._step(c, TURN_UP), TURN_UP)
            dn = self._ray(self._step(c, TURN_DOWN), TURN_DOWN)
            v = min(v, self.rc + min(up, dn))
        return max(e, v)


class _FastCostToGo(_CostToGoH):
    """:class:`_CostToGoH` for the fast search: the same values, computed by the same float
    operations in the same order (so the memo fills alike and h is bit for bit the same), with
    E read through a memoryview, the ray walk inlined, and h kept per state once computed (a
    state's h never changes after its first evaluation: its rays are memoised then)."""

    def __init__(self, base: _CostToGoH):
        self.__dict__.update(base.__dict__)
        self.memo = {}
        self.memos: list[dict[int, float]] = [{} for _ in range(10)]  # per ray: state -> D
        self.ev = memoryview(self.e)
        self.known: dict[int, float] = {}

    def _ray(self, c: int, ray: int) -> float:
        memo, e, joins, manip = self.memos[ray], self.ev, self.joins, self.manip
        if ray < 8:
            cost, mode, off = self.tcost[ray], ray, self.toff[ray]
        else:
            cost, mode, off = self.rc, MODE_ROTATE, 0
        path = []
        x, val = c, INF
        if off:  # a translation: straight along the row, column or diagonal
            while True:
                v = memo.get(x)
                if v is not None:
                    val = v
                    break
                if e[x] == INF:
                    break
                path.append(x)
                x += off
        else:
            val = self._turn_walk(c, ray == TURN_UP, memo, path)
        for x in reversed(path):
            # min(join, manip + E, cost + val) as the reference writes it: the same float
            v = manip + e[x]
            w = cost + val
            if w < v:
                v = w
            if x in joins:
                j = self.join(x, mode)
                if j < v:
                    v = j
            memo[x] = val = v
        return val

    def _turn_walk(self, c: int, up: bool, memo: dict[int, float], path: list[int]) -> float:
        """The states of a turn ray from c not yet memoised (into ``path``) and the value where
        it stops (a memoised state, a blocked state, or back at c: inf)."""
        e, layer, last = self.ev, self.layer, self.k_bins - 1
        wrap = last * layer
        x = c
        for _ in range(self.k_bins + 1):
            v = memo.get(x)
            if v is not None:
                return v
            if e[x] == INF:
                return INF
            path.append(x)
            if up:
                x = x - wrap if x // layer == last else x + layer
            else:
                x = x + wrap if x // layer == 0 else x - layer
            if x == c:  # turned full circle
                return INF
        return INF

    def __getitem__(self, s: int) -> float:
        v = self.known.get(s)
        if v is None:
            v = self.known[s] = _CostToGoH.__getitem__(self, s)
        return v


class _FastPotential:
    """:class:`_PotentialH`'s values through memoryviews (no numpy scalar per look-up)."""

    def __init__(self, base: _PotentialH):
        self.h3 = memoryview(base.h3)
        self.hmode = [memoryview(np.ascontiguousarray(a)) for a in base.hmode]
        self.layer, self.n = base.layer, base.n

    def __getitem__(self, s: int) -> float:
        if s >= self.n:
            return 0.0
        c, m = divmod(s, N_MODES)
        v = self.h3[c]
        if v == INF:
            return INF
        return v + self.hmode[m][c % self.layer]


class _FastSearch:
    """The object search of :func:`weighted_astar` with :class:`_ObjectMoves`, specialised: the
    same states, moves, costs, f (with pathmax), tie-breaking (f, then h, then g, then the
    state), re-opening and pruning, so the same expansions in the same order and the same
    route (``tests/unit/test_route_speed.py`` checks it against that reference). Faster
    because each lattice cell's checked moves (successor cell, mode, cost) are found once per
    planner, not once per expansion of each of its 11 modes; h is read once per state; the
    tables are read through memoryviews; and the loop is one function with local names."""

    def __init__(self, planner: RoutePlanner):
        self.pl = planner
        h = planner._h_obj
        self.h: _FastCostToGo | _FastPotential
        if isinstance(h, _CostToGoH):
            self.h = _FastCostToGo(h)
        else:
            assert h is not None
            self.h = _FastPotential(h)
        self.free = memoryview(planner._free_p)
        self.margin = memoryview(planner._margin_p)
        self.succ: dict[int, tuple[int, ...]] = {}
        k_bins, layer = planner.cspace.heading_bins, planner._layer
        manip, rc = planner.params.manipulation_cost, planner._rot_cost
        base = [*planner._tcost, rc, rc, rc, rc]
        #: per move code: cell offset, mode, cost, cost with a re-arrangement
        self.moves = (
            [*planner._toff, layer, -layer, -(k_bins - 1) * layer, (k_bins - 1) * layer],
            [*range(8), MODE_ROTATE, MODE_ROTATE, MODE_ROTATE, MODE_ROTATE],
            base,
            [b + manip for b in base],
        )

    def successors(self, c: int) -> tuple[int, ...]:
        """The free, checked lattice moves out of padded cell c, in the reference's order, as
        move codes (cached per planner; small ints, so the cache stays small): 0-7 the
        translations, 8 / 9 a turn up / down, 10 / 11 the same wrapping round the heading bins
        (their offsets, modes and costs are in :attr:`moves`)."""
        pl, free, margin = self.pl, self.free, self.margin
        k_bins, layer = pl.cspace.heading_bins, pl._layer
        ok = pl._push_ok[c // layer] if pl._push_ok is not None else [True] * 8
        cands = [(d, c + pl._toff[d]) for d in range(8) if ok[d]]
        if k_bins > 1:
            k = c // layer
            cands.append(
                (TURN_UP + 2 * (k == k_bins - 1), c + self.moves[0][8 + 2 * (k == k_bins - 1)])
            )
            if k_bins > 2:
                cands.append((TURN_DOWN + 2 * (k == 0), c + self.moves[0][9 + 2 * (k == 0)]))
        cands = [(mv, c2) for mv, c2 in cands if free[c2]]
        todo = [i for i, (_, c2) in enumerate(cands) if not (margin[c] and margin[c2])]
        bad: set[int] = set()
        if todo:
            k, iy, ix = pl._unflat(c)
            asked = [cands[i][0] - 2 if cands[i][0] >= 10 else cands[i][0] for i in todo]
            res = pl.cspace.moves_free(k, iy, ix, asked)
            bad = {i for i, ok in zip(todo, res, strict=True) if not ok}
        got = self.succ[c] = tuple(mv for i, (mv, _) in enumerate(cands) if i not in bad)
        return got

    def extra_moves(self, m: int, c: int, reach: list[_Join]) -> list[tuple[int, float]]:
        """(state, cost) of the moves that are not lattice moves: the virtual start's ways to
        the lattice, a lattice state's way to the goal (the reference's costs)."""
        manip = self.pl.params.manipulation_cost
        if c >= self.pl._n:
            return [
                (j.state * N_MODES + (j.modes[-1] if j.modes else MODE_START),
                 j.cost + manip * j.changes)
                for j in reach
            ]  # fmt: skip
        j = self.pl._goal_joins.get(c)
        if j is None:
            return []
        turn_in = bool(j.modes) and _arrival_charge(m, j.modes[0])
        return [(self.pl._n * N_MODES + 1, j.cost + manip * (j.changes + turn_in))]

    def run(
        self, reach: list[_Join], wg: float, wh: float, pathmax: bool, reopen: bool,
        max_expanded: int, trace: bool,
    ) -> SearchOutcome:  # fmt: skip
        """The search from the virtual start (the states of :class:`_ObjectMoves`)."""
        n_lattice = self.pl._n
        start = n_lattice * N_MODES
        goal = start + 1
        gbest: dict[int, float] = {start: 0.0}
        parent: dict[int, int] = {start: -1}
        closed: set[int] = set()
        heap: list[tuple[float, float, float, int]] = [(0.0, 0.0, 0.0, start)]
        expand, relax = self._expanders(gbest, parent, closed, heap, (wg, wh, pathmax, reopen))
        special = set(self.pl._goal_joins)
        special.add(n_lattice)
        pop = heapq.heappop
        ftrace: list[float] = []
        expanded = reexpanded = 0
        generated = 1
        while heap:
            f, _, g, s = pop(heap)
            if g > gbest[s]:
                continue
            if s in closed:
                reexpanded += 1
            closed.add(s)
            expanded += 1
            if trace:
                ftrace.append(f)
            if s == goal or expanded >= max_expanded:
                counts = (expanded, generated, reexpanded)
                return self._outcome(s == goal, parent, g, counts, ftrace, s)
            c, m = divmod(s, N_MODES)
            if c < n_lattice:
                generated += expand(s, c, m, g, f)
            if c in special:
                generated += relax(s, self.extra_moves(m, c, reach), g, f)
        return SearchOutcome(None, INF, expanded, generated, reexpanded, ftrace, False)

    def _expanders(self, gbest, parent, closed, heap, search):
        """The two halves of an expansion over the search's tables (closures, for speed):
        ``expand(s, c, m, g, f)`` relaxes the lattice moves of state s (cell c, mode m) with the
        reference's pruning; ``relax(s, moves, g, f)`` the (state, cost) moves given. Both
        return how many states they pushed."""
        wg, wh, pathmax, reopen = search
        h, succ, successors = self.h, self.succ, self.successors
        offs, modes, bases, pluses = self.moves
        manip = self.pl.params.manipulation_cost
        gmin: dict[int, float] = {}
        push, inf, start_mode = heapq.heappush, INF, MODE_START

        def expand(s: int, c: int, m: int, g: float, f: float) -> int:
            n = 0
            for mv in succ.get(c) or successors(c):
                c2 = c + offs[mv]
                mode = modes[mv]
                g2 = g + (bases[mv] if m == mode or m == start_mode else pluses[mv])
                gm = gmin.get(c2, inf)
                if g2 >= gm + manip:
                    continue
                if g2 < gm:
                    gmin[c2] = g2
                t = c2 * N_MODES + mode
                h2 = h[t]
                if h2 < inf and g2 < gbest.get(t, inf) and (reopen or t not in closed):
                    gbest[t] = g2
                    parent[t] = s
                    f2 = wg * g2 + wh * h2
                    push(heap, (f if pathmax and f2 < f else f2, h2, g2, t))
                    n += 1
            return n

        def relax(s: int, moves: list[tuple[int, float]], g: float, f: float) -> int:
            n = 0
            for t, cost in moves:
                g2 = g + cost
                h2 = h[t]
                if h2 < inf and g2 < gbest.get(t, inf) and (reopen or t not in closed):
                    gbest[t] = g2
                    parent[t] = s
                    f2 = wg * g2 + wh * h2
                    push(heap, (f if pathmax and f2 < f else f2, h2, g2, t))
                    n += 1
            return n

        return expand, relax

    @staticmethod
    def _outcome(found, parent, g, counts, ftrace, s) -> SearchOutcome:
        expanded, generated, reexpanded = counts
        if found:
            return SearchOutcome(_unwind(parent, s), g, expanded, generated, reexpanded, ftrace,
                                 False)  # fmt: skip
        return SearchOutcome(None, INF, expanded, generated, reexpanded, ftrace, True)


class RoutePlanner:
    """The object's route planner for one C-space and one goal: build once, plan from any start.

    cspace: from :func:`build_object_cspace` (its resolution and heading bins must match
    ``params``); goal: the object-frame goal pose (x m, y m, theta rad); params: the ``[route]``
    section. Building checks the goal, finds the ways to reach it exactly from the lattice and
    computes the heuristic tables (for ``cost_to_go`` the lattice cost-to-go, the costly part:
    about 0.3 s at 128 x 128 x 36, 1 s at 256^2, 5 s at 512^2); then :meth:`plan` only searches,
    and with the default heuristic the search expands little more than the route itself. Moves
    checked exactly are cached on the C-space, so re-plans from nearby starts (transport) are
    cheaper still. ``turn_bound=False`` drops the manipulation bound from h (the paper's bare
    potentials). Raises ValueError for parameters that do not fit (weights, heuristic name,
    grid). :meth:`from_config` builds one for a fleet config's object and goal.
    """

    @classmethod
    def from_config(
        cls,
        cfg: FleetConfig,
        goal: ArrayLike | None = None,
        cspace: ObjectCSpace | None = None,
        push: PushDirections | None = None,
    ) -> RoutePlanner:
        """A planner toward ``goal`` (default ``object.goal``) for the config's world, obstacles,
        object and largest robot, with its ``[route]`` parameters; pass ``cspace`` (from
        :func:`object_cspace`) to share one C-space between goals, ``push`` to keep to the
        ways the fleet can push the object."""
        cs = cspace if cspace is not None else object_cspace(cfg)
        return cls(cs, cfg.object.goal if goal is None else goal, cfg.route, push=push)

    def __init__(
        self,
        cspace: ObjectCSpace,
        goal: ArrayLike,
        params: RouteSection,
        *,
        turn_bound: bool = True,
        push: PushDirections | None = None,
    ):
        kind, wg, wh = params.heuristic, float(params.wg), float(params.wh)
        _check_weights(wg, wh)
        if kind not in HEURISTICS:
            raise ValueError(f"heuristic: expected one of {HEURISTICS}, got {kind!r}")
        if (
            abs(cspace.frame.resolution - params.resolution) > 1e-12
            or cspace.heading_bins != params.heading_bins
        ):
            raise ValueError(
                "cspace: built at resolution "
                f"{cspace.frame.resolution} m / {cspace.heading_bins} headings, params ask for "
                f"{params.resolution} m / {params.heading_bins}"
            )
        self.cspace = cspace
        self.params = params
        self.kind, self.wg, self.wh = kind, wg, wh
        self.goal = _pose3(goal, "goal")
        self.push = push
        self._push_ok: list[list[bool]] | None = None  # per heading bin and move: pushable
        fr = cspace.frame
        self._w, self._h = fr.nx + 2, fr.ny + 2
        self._layer = self._w * self._h
        self._n = cspace.heading_bins * self._layer
        self.goal_reason = self._check_end(self.goal, "goal")
        self._goal_joins: dict[int, _Join] = {}
        if not self.goal_reason:
            self._goal_joins = {j.state: j for j in self._joins(self.goal, True)}
            if not self._goal_joins:
                self.goal_reason = (
                    "goal unreachable: no lattice state next to the goal joins it without a "
                    "collision (the goal is too tight for the resolution)"
                )
        self._free_p = _padded(cspace.free)
        self._margin_p = _padded(cspace.margin_free)
        self._rot_cost = cspace.step / params.yaw_rate
        self._toff = [int(dy * self._w + dx) for dx, dy in MOVES_8]
        self._tcost = [fr.resolution * math.hypot(dx, dy) / params.speed for dx, dy in MOVES_8]
        self._h_obj: _PotentialH | _CostToGoH | None = None
        self._fast: _FastSearch | None = None
        if not self.goal_reason:
            self._h_obj = self._heuristic(turn_bound)

    # -- poses and joins ----------------------------------------------------------------------
    def _unflat(self, c: int) -> tuple[int, int, int]:
        k, p = divmod(c, self._layer)
        iy, ix = divmod(p, self._w)
        return k, iy - 1, ix - 1

    def _unpadded(self, c: int) -> int:
        k, iy, ix = self._unflat(c)
        return (k * self.cspace.frame.ny + iy) * self.cspace.frame.nx + ix

    def _flat(self, k: int, iy: int, ix: int) -> int:
        return k * self._layer + (iy + 1) * self._w + ix + 1

    def _lattice_ref(self, c: int) -> FloatArray:
        k, iy, ix = self._unflat(c)
        x, y = self.cspace.frame.center(iy, ix)
        return np.array([x, y, k * self.cspace.step])

    def _check_end(self, pose: FloatArray, name: str) -> str:
        cs = self.cspace
        if cs.cell_of(pose) is None:
            return f"{name} lies outside the world bounds"
        if not cs.is_free(pose):
            d, what = cs.clearance(pose)
            ring = 2.0 * cs.robot_radius
            return (
                f"{name} pose collides: the object there comes within {max(d, 0.0):.3f} m of "
                f"{what}; the robots around it need {ring:.3f} m"
            )
        return ""

    def _escape(self, pose: FloatArray) -> FloatArray | None:
        """Where an object whose start leaves the robots no room (it touches or nears an
        obstacle: an arrest against a pillar) first goes: the nearest pose, by one straight
        move at its heading (ESCAPE_DIRECTIONS directions, up to ESCAPE_REACH robot diameters),
        that is free with the robots' ring, the object overlapping no obstacle on the way (it may
        slide along the one it touches), with room for a pusher behind it (a robot fits against
        a face it can push that way from: ``ObjectCSpace.pusher_room``). None when the object
        overlaps an obstacle already or no direction clears it."""
        cs = self.cspace
        if cs.overlap(pose) > OVERLAP_TOL:
            return None
        ring = 2.0 * cs.robot_radius
        step = 0.5 * cs.frame.resolution
        best: tuple[float, FloatArray] | None = None
        for a in np.arange(ESCAPE_DIRECTIONS) * (2.0 * math.pi / ESCAPE_DIRECTIONS):
            u = np.array([math.cos(a), math.sin(a), 0.0])
            if not cs.pusher_room(pose, u, ESCAPE_CONE):
                continue  # no robot fits where it could push the object this way
            s = step
            while s <= ESCAPE_REACH * ring and (best is None or s < best[0]):
                p = pose + s * u
                if cs.cell_of(p) is None or cs.overlap(p) > OVERLAP_TOL:
                    break
                if cs.is_free(p):
                    best = (s, p)
                    break
                s += step
        return None if best is None else best[1]

    def _joins(self, pose: FloatArray, to_goal: bool, every: bool = False) -> list[_Join]:
        """Collision-free ways between an exact pose and the lattice states around it.

        Candidates: the two nearest heading bins at the pose's cell and its 8 neighbours. Each
        way is one turn in place and one straight move: the turn first (at the pose's position,
        then the move at the bin's heading) or, if that collides, the move first (at the pose's
        heading, then the turn at the cell centre). Both pieces are checked exactly. ``seq`` runs
        from the exact pose to the lattice state; a goal's way is travelled backwards (``modes``
        are in the order travelled). Once the search keeps to the ways the fleet can push
        (:meth:`_restrict`), only those, unless ``every``.
        """
        cs, p = self.cspace, self.params
        ref = cs.ref_pose(pose)
        cell = cs.frame.cell_of(ref[:2])
        if cell is None:
            return []
        kf = math.floor(ref[2] / cs.step)
        bins = sorted({kf % cs.heading_bins, (kf + 1) % cs.heading_bins})
        cand = [
            (k, cell[0] + dy, cell[1] + dx)
            for k in bins
            for dy in (-1, 0, 1)
            for dx in (-1, 0, 1)
            if 0 <= cell[0] + dy < cs.frame.ny
            and 0 <= cell[1] + dx < cs.frame.nx
            and cs.free[k, cell[0] + dy, cell[1] + dx]
        ]
        if not cand:
            return []
        cells = np.array(cand)
        n = len(cells)
        xs, ys = cs.frame.centers()
        turns = np.atleast_1d(geometry.wrap_angle(cells[:, 0] * cs.step - ref[2]))
        target = np.stack([xs[cells[:, 2]], ys[cells[:, 1]], ref[2] + turns], 1)
        steps = target[:, :2] - ref[:2]
        here = np.repeat(ref[None], n, 0)
        chk = cs.checker
        # the turn first: exact pose -> (its position, the bin's heading) -> the lattice state
        via1 = np.column_stack([here[:, :2], target[:, 2]])
        ok1 = chk.poses_free(via1)
        ok1[ok1] = chk.rotations_free(here[ok1], turns[ok1])
        ok1[ok1] = chk.translations_free(via1[ok1], steps[ok1])
        # the move first: exact pose -> (the cell centre, its heading) -> the lattice state
        via2 = np.column_stack([target[:, :2], here[:, 2]])
        ok2 = ~ok1 & chk.poses_free(via2)
        ok2[ok2] = chk.translations_free(here[ok2], steps[ok2])
        ok2[ok2] = chk.rotations_free(via2[ok2], turns[ok2])
        max_turn = min(cs.step, math.pi / 4)
        out = []
        for i in np.flatnonzero(ok1 | ok2):
            k, iy, ix = (int(v) for v in cells[i])
            cost = abs(float(turns[i])) / p.yaw_rate + float(np.hypot(*steps[i])) / p.speed
            if ok1[i]:
                seq = _split_turn(ref, float(turns[i]), max_turn)
            else:
                seq = [via2[i], *_split_turn(via2[i], float(turns[i]), max_turn)[:-1]]
            pieces = [MODE_ROTATE, "move"] if ok1[i] else ["move", MODE_ROTATE]
            sizes = {MODE_ROTATE: abs(float(turns[i])), "move": float(np.hypot(*steps[i]))}
            v = -steps[i] if to_goal else steps[i]
            move = _step_mode(v)
            modes = [move if q == "move" else q for q in pieces if sizes[q] > 1e-12]
            heading = float(target[i, 2]) if ok1[i] else float(ref[2])  # where it moves
            angle = math.atan2(v[1], v[0]) - heading if sizes["move"] > 1e-12 else None
            ordered = tuple(modes[::-1] if to_goal else modes)
            out.append(_Join(self._flat(k, iy, ix), cost, seq, ordered, angle))
        if self._push_ok is not None and not every:  # only ways the fleet can push
            out = [j for j in out if self._pushable(j.push_angle)]
            have = {j.state for j in out}
            out += self._turned_joins(ref, cells[[self._flat(*c) not in have for c in cand]],
                                      to_goal)  # fmt: skip
        return out

    def _turned_joins(self, ref: FloatArray, cells: NDArray[np.int_], to_goal: bool) -> list[_Join]:
        """Ways the fleet can push between an exact pose (``ref``, the C-space's reference
        pose) and lattice states (``cells``: (k, iy, ix)) whose straight piece it cannot push
        at either end's heading: a turn in place to a heading at which it can push the object
        that way, the straight move, a turn to the lattice heading (the three pieces checked
        exactly; for a goal travelled backwards). The pushable heading that turns least is
        tried first, then the next (three at most)."""
        cs, p, chk = self.cspace, self.params, self.cspace.checker
        assert self.push is not None
        xs, ys = cs.frame.centers()
        max_turn = min(cs.step, math.pi / 4)
        pushable = self.push.pushable_angles()
        out: list[_Join] = []
        for k, iy, ix in (tuple(int(v) for v in c) for c in cells):
            step = np.array([xs[ix], ys[iy]]) - ref[:2]
            length = float(np.hypot(*step))
            if length <= 1e-12 or not pushable:
                continue
            v = -step if to_goal else step
            bin_heading = ref[2] + geometry.wrap_angle(k * cs.step - ref[2])
            tries = []
            for a in pushable:
                phi = ref[2] + geometry.wrap_angle(math.atan2(v[1], v[0]) - a - ref[2])
                t1 = float(phi - ref[2])
                t2 = float(geometry.wrap_angle(bin_heading - phi))
                tries.append((abs(t1) + abs(t2), t1, t2, phi, a))
            for _, t1, t2, phi, a in sorted(tries)[:3]:
                via_a = np.array([ref[0], ref[1], phi])
                via_b = np.array([xs[ix], ys[iy], phi])
                ok = (
                    chk.rotations_free(ref[None], np.array([t1]))[0]
                    and chk.poses_free(via_a[None])[0]
                    and chk.translations_free(via_a[None], step[None])[0]
                    and chk.poses_free(via_b[None])[0]
                    and chk.rotations_free(via_b[None], np.array([t2]))[0]
                )
                if not ok:
                    continue
                seq = [
                    *_split_turn(ref, t1, max_turn),
                    via_b,
                    *_split_turn(via_b, t2, max_turn)[:-1],
                ]
                pieces = [(MODE_ROTATE, abs(t1)), (_step_mode(v), length), (MODE_ROTATE, abs(t2))]
                modes = [m for m, size in pieces if size > 1e-12]
                ordered = tuple(modes[::-1] if to_goal else modes)
                cost = (abs(t1) + abs(t2)) / p.yaw_rate + length / p.speed
                out.append(_Join(self._flat(k, iy, ix), cost, seq, ordered, a))
                break
        return out

    # -- pushing (issue 34, item 9) --------------------------------------------------------------
    def _pushable(self, angle: float | None) -> bool:
        """Whether the fleet can push the object along ``angle`` (rad, object frame; None: no
        straight move)."""
        return angle is None or self.push is None or self.push.can_push(angle)

    def _unpushable_move(self, wp: FloatArray) -> bool:
        """Whether a route's waypoints ask for a straight move the fleet cannot push."""
        step = np.diff(wp, axis=0)
        for (dx, dy, dth), heading in zip(step, wp[:-1, 2], strict=True):
            if abs(geometry.wrap_angle(dth)) > 1e-12:
                continue  # a turn in place (the frame's origin swings round the reference)
            if math.hypot(dx, dy) > 1e-9 and not self._pushable(math.atan2(dy, dx) - heading):
                return True
        return False

    def _restrict(self) -> None:
        """From now on the search moves the object only where the fleet can push it: each
        lattice translation by the heading it is made at, and the start's and goal's ways."""
        cs = self.cspace
        angles = [math.atan2(dy, dx) for dx, dy in MOVES_8]
        self._push_ok = [
            [self._pushable(a - k * cs.step) for a in angles] for k in range(cs.heading_bins)
        ]
        if self._goal_joins:
            self._goal_joins = {j.state: j for j in self._joins(self.goal, True)}
        self._fast = None

    # -- heuristics ---------------------------------------------------------------------------
    def _heuristic(self, turn_bound: bool) -> _PotentialH | _CostToGoH:
        cs, p = self.cspace, self.params
        joins = list(self._goal_joins.values())
        cells = np.array([self._unflat(j.state) for j in joins])
        if self.kind != "cost_to_go":
            return self._potential(cells, turn_bound)
        manip = p.manipulation_cost if turn_bound else 0.0
        entries: dict[int, list[tuple[float, int]]] = {}
        seed_cost, seed_kind = [], []
        for j in joins:
            first = j.modes[0] if j.modes else -1
            base = j.cost + manip * j.changes
            entries.setdefault(j.state, []).append((base, first))
            # a way that begins off the lattice's directions is always entered by a change
            seed_cost.append(base + manip * (first == MODE_JOIN))
            seed_kind.append(first if 0 <= first <= MODE_ROTATE else -1)
        e = heuristics.lattice_cost_to_go(
            cs.free,
            (cells, np.array(seed_cost)),
            cs.frame.resolution / p.speed,
            self._rot_cost,
            manip,
            seed_kinds=np.array(seed_kind),
        )
        return _CostToGoH(self, _padded(e, INF), entries, manip)

    def _potential(self, cells: NDArray[np.int_], turn_bound: bool) -> _PotentialH:
        """The paper's potential (x, y) / speed + heading change / yaw_rate + manipulation
        bound."""
        cs, p = self.cspace, self.params
        fr = cs.frame
        free2d = cs.free.any(axis=0)
        gref = cs.ref_pose(self.goal)
        gcell = fr.cell_of(gref[:2])
        assert gcell is not None
        if self.kind == "euclid":
            gy = (gref[1] - fr.y0) / fr.resolution - 0.5
            gx = (gref[0] - fr.x0) / fr.resolution - 0.5
            table = heuristics.euclid(free2d, (gy, gx), fr.resolution)
        elif self.kind == "wavefront":
            xs, ys = fr.centers()
            cen = np.stack([xs[cells[:, 2]], ys[cells[:, 1]]], 1)
            lengths = np.linalg.norm(cen - gref[:2], axis=1)
            table = heuristics.wavefront(
                free2d, gcell, fr.resolution, seeds=(cells[:, 1:], lengths)
            )
        else:
            table = heuristics.skeleton_wavefront(free2d, gcell, fr.resolution)
        dk = np.abs(geometry.wrap_angle(gref[2] - np.arange(cs.heading_bins) * cs.step))
        h3 = dk[:, None, None] / p.yaw_rate + table[None] / p.speed
        h3 = np.where(cs.free, h3, INF)
        goal_mask = np.zeros_like(free2d)
        goal_mask[cells[:, 1], cells[:, 2]] = True
        hmode = self._manipulation_bound(free2d, goal_mask, p.manipulation_cost * turn_bound)
        return _PotentialH(_padded(h3, INF), hmode, self._layer, self._n)

    def _manipulation_bound(
        self, free2d: NDArray[np.bool_], goal_mask: NDArray[np.bool_], manip: float
    ) -> list[FloatArray]:
        """Per mode, per padded (x, y) cell: a lower bound (s) on the manipulation cost to pay.

        Translation mode d: ``manip`` times the fewest direction changes when the last move was
        d (:func:`controller.planning.heuristics.turn_bounds` over the cells free at some
        heading, 0 where the goal is joined). Rotating: one change to start translating again,
        plus the fewest after it, unless the goal is joined there. Start: the fewest changes
        with the first direction free. Every change of mode is charged ``manip`` and every
        change of translation direction needs one, so the bound is admissible (and consistent).
        """
        size = self._h * self._w
        if manip <= 0:
            zero = np.zeros(size)
            return [zero] * N_MODES
        t, v = heuristics.turn_bounds(free2d, goal_mask, MOVES_8)
        rot = np.where(goal_mask, 0.0, 1.0 + v)
        out = []
        for layer_val in [*t, rot, v, rot]:
            pad = np.full((self._h, self._w), INF)
            pad[1:-1, 1:-1] = manip * layer_val
            out.append(pad.ravel())
        return out

    # -- the search ---------------------------------------------------------------------------

    def plan(
        self,
        start: ArrayLike,
        *,
        pathmax: bool = True,
        max_expanded: int = 20_000_000,
        trace: bool = False,
        reference: bool = False,
    ) -> RouteResult:
        """The route from the object-frame ``start`` pose to the goal (see :class:`RouteResult`).

        Never raises for an unreachable goal or a colliding start: the result's status is
        "no_path" with a reason. ``pathmax=False`` turns Eq. 2 off (for tests); ``trace``
        records f of each expansion. ``reference=True`` runs the search through the generic
        :func:`weighted_astar` and :class:`_ObjectMoves` (the slow reference the fast search is
        checked against, for tests and ``bench/route_speed.py``): same route, same counts.
        """
        kind, wg, wh = self.kind, self.wg, self.wh
        start_p = _pose3(start, "start")
        if self.goal_reason:
            return _no_path(self.goal_reason, kind, wg, wh)
        reason = self._check_end(start_p, "start")
        if reason:
            escape = self._escape(start_p) if "collides" in reason else None
            if escape is None:
                return _no_path(reason, kind, wg, wh)
            rest = self.plan(
                escape, pathmax=pathmax, max_expanded=max_expanded, trace=trace, reference=reference
            )
            return _after_escape(start_p, rest, self.params) if rest.status == "ok" else rest
        if np.allclose(start_p, self.goal, atol=1e-12):
            wp = np.vstack([start_p, self.goal])
            return RouteResult("ok", waypoints=wp, subgoals=wp[1:], cost=0.0, heuristic=kind,
                               wg=wg, wh=wh)  # fmt: skip
        joins = self._joins(start_p, False)
        assert self._h_obj is not None
        if not reference and self._fast is None:
            self._fast = _FastSearch(self)
        h = self._h_obj if reference or self._fast is None else self._fast.h
        reach = [j for j in joins if h[j.state * N_MODES + MODE_START] < INF]  # E < inf
        if self.kind != "cost_to_go":  # the potentials do not know the lattice's components
            labels = self.cspace.labels.ravel()
            goal_labels = {int(labels[self._unpadded(c)]) for c in self._goal_joins}
            reach = [j for j in reach if int(labels[self._unpadded(j.state)]) in goal_labels]
        if not reach:
            return self._unreached(start_p, bool(joins))
        reopen = reopens(wg, wh, self.params.reopen)
        if self._fast is not None and not reference:
            out = self._fast.run(reach, wg, wh, pathmax, reopen, max_expanded, trace)
        else:
            out = self._reference_search(reach, pathmax, reopen, max_expanded, trace)
        counts = out.counts()
        if out.path is None:
            if self._push_ok is not None and not out.limited:
                return self._too_heavy(**counts)
            return _no_path(out.reason(max_expanded), kind, wg, wh, **counts)
        res = self._result(start_p, out.path, out.cost, {j.state: j for j in reach}, counts)
        if self.push is not None and self._push_ok is None and self._unpushable_move(res.waypoints):
            # the fleet cannot push the object along this route: from now on, only the ways
            # it can (a heavy object turned to present a face where enough robots fit)
            self._restrict()
            return self.plan(start_p, pathmax=pathmax, max_expanded=max_expanded, trace=trace,
                             reference=reference)  # fmt: skip
        return replace(res, push_limited=self._push_ok is not None)

    def _unreached(self, start_p: FloatArray, joined: bool) -> RouteResult:
        """No start state the search could begin from: why (``joined``: some joined)."""
        if self._push_ok is not None and self._joins(start_p, False, every=True):
            return self._too_heavy()
        why = (
            "start and goal lie in different free regions of the C-space"
            if joined
            else "no lattice state next to the start joins it without a collision"
        )
        return _no_path(f"goal unreachable: {why}", self.kind, self.wg, self.wh)

    def _too_heavy(self, **counts: Any) -> RouteResult:
        """No way the fleet can push the object: why, in figures (``PushDirections``)."""
        assert self.push is not None
        detail = self.push.too_heavy_detail()
        return _no_path(detail, self.kind, self.wg, self.wh, too_heavy=True, **counts)

    def _reference_search(
        self, reach: list[_Join], pathmax: bool, reopen: bool, max_expanded: int, trace: bool
    ) -> SearchOutcome:
        """The object search through the generic :func:`weighted_astar` (the reference)."""
        s_virtual = self._n * N_MODES
        assert self._h_obj is not None
        return weighted_astar(
            s_virtual,
            s_virtual + 1,
            self._h_obj,
            _ObjectMoves(self, reach),
            wg=self.wg,
            wh=self.wh,
            pathmax=pathmax,
            reopen=reopen,
            max_expanded=max_expanded,
            trace=trace,
        )

    def _result(
        self,
        start_p: FloatArray,
        path: list[int],
        cost: float,
        start_joins: dict[int, _Join],
        counts: dict[str, Any],
    ) -> RouteResult:
        cs, p = self.cspace, self.params
        states = path[1:-1]
        cells = [s // N_MODES for s in states]
        modes = [s % N_MODES for s in states]
        first, last = start_joins[cells[0]], self._goal_joins[cells[-1]]
        ref = [cs.ref_pose(start_p), *first.seq]
        ref += [self._lattice_ref(c) for c in cells]
        ref += [*last.seq[::-1], cs.ref_pose(self.goal)]
        ref_arr = np.array(ref)
        step = np.diff(ref_arr, axis=0)
        step[:, 2] = geometry.wrap_angle(step[:, 2])
        keep = np.r_[True, np.any(np.abs(step) > 1e-12, axis=1)]
        ref_arr = ref_arr[keep]
        wp = cs.frame_pose(ref_arr)
        wp[:, 2] = geometry.wrap_angle(wp[:, 2])
        wp[0], wp[-1] = start_p, self.goal
        if len(wp) == 1:
            wp = np.vstack([start_p, self.goal])
            ref_arr = np.vstack([ref_arr, ref_arr])
        kinds = _move_kinds(ref_arr)
        seq = [MODE_START, *first.modes, *modes[1:], *last.modes]
        manip = sum(1 for a, b in zip(seq[:-1], seq[1:], strict=True) if a != b and a != MODE_START)
        length = float(np.sum(np.linalg.norm(np.diff(ref_arr[:, :2], axis=0), axis=1)))
        return ok_result(
            wp, kinds, p.subgoal_spacing, cost, length, manip, (self.kind, self.wg, self.wh), counts
        )


# the start's escape (RoutePlanner._escape): directions tried, reach in robot diameters, and the
# overlap (m²) still counted as touching
ESCAPE_DIRECTIONS = 16
ESCAPE_REACH = 4.0
ESCAPE_CONE = math.radians(60.0)  # a pusher's face: its inward normal this near the move
OVERLAP_TOL = 1e-6


def _after_escape(start: FloatArray, rest: RouteResult, p: RouteSection) -> RouteResult:
    """``rest`` (planned from the escape pose) with the escape's straight move before it: one
    more subgoal (the escape pose, where the robots re-arrange), its time and length."""
    d = float(np.hypot(*(rest.waypoints[0, :2] - start[:2])))
    return replace(
        rest,
        waypoints=np.vstack([start, rest.waypoints]),
        subgoals=np.vstack([rest.waypoints[:1], rest.subgoals]),
        cost=rest.cost + d / p.speed + p.manipulation_cost,
        length_m=rest.length_m + d,
        manipulations=rest.manipulations + 1,
    )


def _padded(a: NDArray[Any], fill: Any = False) -> NDArray[Any]:
    """A (K, ny, nx) table with one ``fill`` cell around each layer, flattened."""
    k_bins, ny, nx = a.shape
    out = np.full((k_bins, ny + 2, nx + 2), fill, dtype=a.dtype)
    out[:, 1:-1, 1:-1] = a
    return out.ravel()


class _ObjectMoves:
    """moves_of(s, g) of the object search (see :func:`weighted_astar`) over the states
    ``cell * N_MODES + mode`` and the virtual start and goal: the lattice moves to free states
    that pass the exact sweep test (unless both ends are margin-free), the start's and the
    goal's ways, each with its manipulation charge. A successor whose g exceeds the best g of
    its cell (any mode) by a re-arrangement or more is dropped: that mode can do nothing the
    other cannot do for at most one re-arrangement more."""

    def __init__(self, planner: RoutePlanner, start_joins: list[_Join]):
        self.pl = planner
        self.start_joins = start_joins
        self.s_virtual = planner._n * N_MODES
        self.manip = planner.params.manipulation_cost
        self.gmin: dict[int, float] = {}

    def candidates(self, c: int) -> list[tuple[int, int]]:
        """(move, cell) of the moves from lattice cell c to free cells (not yet checked)."""
        pl = self.pl
        k_bins, layer = pl.cspace.heading_bins, pl._layer
        ok = pl._push_ok[c // layer] if pl._push_ok is not None else [True] * 8
        out = [(d, c + pl._toff[d]) for d in range(8) if ok[d]]
        if k_bins > 1:
            k = c // layer
            out.append((TURN_UP, c - (k_bins - 1) * layer if k == k_bins - 1 else c + layer))
            if k_bins > 2:
                out.append((TURN_DOWN, c + (k_bins - 1) * layer if k == 0 else c - layer))
        free = pl._free_p
        return [(mv, c2) for mv, c2 in out if free[c2]]

    def checked(self, c: int, cands: list[tuple[int, int]]) -> list[tuple[int, int]]:
        """The candidates whose swept footprint is clear (margin-free pairs need no test)."""
        margin = self.pl._margin_p
        if margin[c]:
            todo = [i for i, (_, c2) in enumerate(cands) if not margin[c2]]
        else:
            todo = list(range(len(cands)))
        if not todo:
            return cands
        k, iy, ix = self.pl._unflat(c)
        res = self.pl.cspace.moves_free(k, iy, ix, [cands[i][0] for i in todo])
        bad = {i for i, ok in zip(todo, res, strict=True) if not ok}
        return [mc for i, mc in enumerate(cands) if i not in bad]

    def __call__(self, s: int, g: float) -> list[tuple[int, float]]:
        manip = self.manip
        if s == self.s_virtual:
            return [
                (j.state * N_MODES + (j.modes[-1] if j.modes else MODE_START) - s,
                 j.cost + manip * j.changes)
                for j in self.start_joins
            ]  # fmt: skip
        c, m = divmod(s, N_MODES)
        out = []
        for mv, c2 in self.checked(c, self.candidates(c)):
            mode = mv if mv < 8 else MODE_ROTATE
            cost = self.pl._tcost[mv] if mv < 8 else self.pl._rot_cost
            if m != mode and m != MODE_START:
                cost += manip
            if self._keep(c2, g + cost):
                out.append((c2 * N_MODES + mode - s, cost))
        j = self.pl._goal_joins.get(c)
        if j is not None:
            turn_in = bool(j.modes) and _arrival_charge(m, j.modes[0])
            out.append((self.s_virtual + 1 - s, j.cost + manip * (j.changes + turn_in)))
        return out

    def _keep(self, c2: int, g2: float) -> bool:
        gm = self.gmin.get(c2, INF)
        if g2 >= gm + self.manip:
            return False
        if g2 < gm:
            self.gmin[c2] = g2
        return True


def _pose3(pose: ArrayLike, name: str) -> FloatArray:
    try:
        p = np.asarray(pose, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a pose [x, y, theta], got {pose!r}") from exc
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: expected a pose [x, y, theta] of finite numbers, got {pose!r}")
    return p


def object_cspace(cfg: FleetConfig) -> ObjectCSpace:
    """The object's C-space for a fleet config: its world bounds and obstacles, the object
    polygon, the largest robot radius, ``route.resolution`` and ``route.heading_bins``."""
    return build_object_cspace(
        cfg.bounds_array(),
        cfg.obstacle_polygons(),
        cfg.object_polygon(),
        cfg.max_robot_radius,
        cfg.route.resolution,
        cfg.route.heading_bins,
    )


def plan_route(
    bounds: ArrayLike,
    obstacles: list[ArrayLike],
    footprint_polygon: ArrayLike,
    robot_radius: float,
    start: ArrayLike,
    goal: ArrayLike,
    params: RouteSection,
    *,
    cspace: ObjectCSpace | None = None,
    pathmax: bool = True,
    turn_bound: bool = True,
    max_expanded: int = 20_000_000,
    trace: bool = False,
) -> RouteResult:
    """Plan the carried object's route from ``start`` to ``goal`` poses in one call.

    bounds [[xmin, ymin], [xmax, ymax]] (m); obstacles: world polygons (n, 2); footprint_polygon:
    the object polygon in its frame (m); robot_radius: the fleet's largest robot radius (m);
    params: the [route] section. ``cspace`` reuses a C-space from :func:`build_object_cspace`
    (then bounds, obstacles, footprint and radius are not used). See :class:`RoutePlanner` for
    the rest; to plan many times toward one goal, build a RoutePlanner once instead.
    """
    if cspace is None:
        cspace = build_object_cspace(
            bounds,
            obstacles,
            footprint_polygon,
            robot_radius,
            params.resolution,
            params.heading_bins,
        )
    planner = RoutePlanner(cspace, goal, params, turn_bound=turn_bound)
    return planner.plan(start, pathmax=pathmax, max_expanded=max_expanded, trace=trace)
