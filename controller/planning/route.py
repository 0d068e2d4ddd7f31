"""Global route planning for the carried object and for single robots (Yamashita et al. §3).

Pure: arrays and frozen dataclasses in, a :class:`RouteResult` out; no I/O, no clock.

The object's search runs over its (x, y, theta) C-space (:mod:`controller.cspace`) with

    f(n') = max(f(n), w_g g(n') + w_h h(n'))        (Eq. 1 with the pathmax of Eq. 2)

so f never decreases along a path, and the expansion order is non-decreasing in f even with an
inconsistent heuristic. ``w_g`` is 0 or 1, ``w_h >= 0``; ``w_h = 0`` is Dijkstra, ``w_g = 0`` is
greedy best-first. Moves are 8-connected (x, y) steps at a fixed heading and one heading bin in
place. Costs are seconds: distance / ``speed``, rotation / ``yaw_rate``, plus
``manipulation_cost`` whenever the travel direction relative to the object changes (a new
translation direction, or switching between translating and turning): the robots around the
object must re-arrange (Yamashita puts the manipulation constraints into the cost function). To
keep that cost exact the search state is (cell, heading, last move), 10 "modes" per cell.

The heuristic h (s) is a distance table from :mod:`controller.heuristics` divided by ``speed``
(the paper's potential normalized by the velocity), plus the smallest heading change to the goal
divided by ``yaw_rate``, plus ``manipulation_cost`` times the fewest changes of travel direction
still needed from this cell and mode (a link distance, :func:`controller.heuristics.turn_bounds`;
``turn_bound=False`` leaves it out). Translation, rotation and manipulation are separate cost
terms, so the sum of three lower bounds is a lower bound: with Euclid or wavefront the heuristic
is admissible and ``w_g = w_h = 1`` returns the optimal cost (the mode term can make it
inconsistent; pathmax and re-opening handle that). The skeleton wavefront is not admissible.

Unreachable goals are answers, not errors: the C-space's connected components are checked first
(exactly the planner's move graph), so an enclosed goal returns ``no_path`` at once.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller import geometry
from controller.config import RouteSection
from controller.planning import heuristics
from controller.planning.cspace import MOVES_8, ObjectCSpace, build_object_cspace

FloatArray = NDArray[np.float64]
INF = math.inf

#: Modes of the object search: 0-7 the translation directions of ``MOVES_8``, then these two.
MODE_ROTATE = 8
MODE_START = 9
N_MODES = 10


@dataclass(frozen=True, eq=False)
class RouteResult:
    """A planned route, or why there is none.

    status: "ok" or "no_path"; reason: empty when ok, else why (human readable).
    waypoints: (k, 3) poses (m, m, rad), one grid move apart; the first and last are the exact
    start and goal. subgoals: (m, 3) poses where the travel direction changes (the robots
    re-arrange there), long straight runs cut every ``subgoal_spacing`` m, ending with the goal.
    cost: seconds (inf when no path); length_m: (x, y) length of the waypoint polyline;
    rotation_rad: total turning; manipulations: number of re-arrangements paid for;
    expanded: nodes expanded (N_open); generated: nodes pushed on the open list;
    f_trace: f of each expanded node in order (only when asked for).
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
    heuristic: str = ""
    wg: float = 1.0
    wh: float = 1.0
    f_trace: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

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
            "heuristic": self.heuristic,
            "wg": self.wg,
            "wh": self.wh,
        }


def _no_path(reason: str, heuristic: str, wg: float, wh: float, **kw: Any) -> RouteResult:
    return RouteResult(status="no_path", reason=reason, heuristic=heuristic, wg=wg, wh=wh, **kw)


def _check_weights(wg: float, wh: float) -> None:
    if wg not in (0.0, 1.0):
        raise ValueError(f"wg: expected 0 or 1, got {wg!r}")
    if not (wh >= 0 and math.isfinite(wh)):
        raise ValueError(f"wh: expected a finite number >= 0, got {wh!r}")


# --------------------------------------------------------------------------- the searches


def _search_object(
    h: list[float],
    hmode: list[list[float]],
    layer: int,
    n_layers: int,
    toff: list[int],
    tcost: list[float],
    rcost: float,
    manip: float,
    start_c: int,
    goal_c: int,
    wg: float,
    wh: float,
    pathmax: bool,
    max_expanded: int,
    trace: bool,
) -> tuple[list[int] | None, float, int, int, list[float], bool]:
    """Weighted A* with pathmax over states ``cell * N_MODES + mode`` (cell = k * layer + p).

    ``h`` (s) per cell is inf on occupied cells and on cells that cannot reach the goal, so one
    lookup both tests a cell and scores it; ``hmode[m]`` (s) per (x, y) cell of a layer adds the
    mode-dependent part (the manipulation bound) for a state entered in mode m.
    Returns (states of the path or None, cost, expanded, generated, f trace, hit the limit).
    """
    big_m = N_MODES
    # per mode: (cell offset, state offset, cost, new mode) of the 8 translations
    tmoves = []
    for m in range(big_m):
        tmoves.append(
            tuple(
                (
                    toff[d],
                    toff[d] * big_m + d,
                    tcost[d] + (0.0 if m in (d, MODE_START) else manip),
                    hmode[d],
                )
                for d in range(8)
            )
        )
    rmove = [rcost + (0.0 if m in (MODE_ROTATE, MODE_START) else manip) for m in range(big_m)]
    rot: list[tuple[int, ...]] = []
    for k in range(n_layers):
        if n_layers == 1:
            rot.append(())
        elif n_layers == 2:
            rot.append((layer if k == 0 else -layer,))
        else:
            up = layer if k < n_layers - 1 else -(n_layers - 1) * layer
            dn = -layer if k > 0 else (n_layers - 1) * layer
            rot.append((up, dn))

    s0 = start_c * big_m + MODE_START
    # g per state, and per cell the best g over its modes: a state whose g exceeds its cell's
    # best by the manipulation cost or more is dominated (switching modes costs exactly that).
    gbest: dict[int, float] = {}
    gmin: dict[int, float] = {}
    parent: dict[int, int] = {s0: -1}
    gbest[s0] = 0.0
    gmin[start_c] = 0.0
    h0 = h[start_c] + hmode[MODE_START][start_c % layer]
    hrot = hmode[MODE_ROTATE]
    heap: list[tuple[float, float, float, int]] = [(wh * h0, h0, 0.0, s0)]
    push, pop = heapq.heappush, heapq.heappop
    ftrace: list[float] = []
    expanded = 0
    generated = 1
    while heap:
        f, _, g, s = pop(heap)
        if g > gbest[s]:
            continue
        c, m = divmod(s, big_m)
        if g > gmin[c] + manip:
            continue
        expanded += 1
        if trace:
            ftrace.append(f)
        if c == goal_c:
            path = [s]
            while parent[path[-1]] >= 0:
                path.append(parent[path[-1]])
            return path[::-1], g, expanded, generated, ftrace, False
        if expanded >= max_expanded:
            return None, INF, expanded, generated, ftrace, True
        base = s - m
        k, p = divmod(c, layer)
        for off, soff, cost, hm in tmoves[m]:
            c2 = c + off
            h2 = h[c2]
            if h2 < INF:
                h2 += hm[p + off]
                g2 = g + cost
                s2 = base + soff
                if g2 < gbest.get(s2, INF):
                    gm = gmin.get(c2, INF)
                    if g2 < gm + manip:
                        gbest[s2] = g2
                        if g2 < gm:
                            gmin[c2] = g2
                        parent[s2] = s
                        f2 = wg * g2 + wh * h2
                        if pathmax and f2 < f:
                            f2 = f
                        push(heap, (f2, h2, g2, s2))
                        generated += 1
        g2 = g + rmove[m]
        hr = hrot[p]
        for off in rot[k]:
            c2 = c + off
            h2 = h[c2]
            if h2 < INF:
                h2 += hr
                s2 = c2 * big_m + MODE_ROTATE
                if g2 < gbest.get(s2, INF):
                    gm = gmin.get(c2, INF)
                    if g2 < gm + manip:
                        gbest[s2] = g2
                        if g2 < gm:
                            gmin[c2] = g2
                        parent[s2] = s
                        f2 = wg * g2 + wh * h2
                        if pathmax and f2 < f:
                            f2 = f
                        push(heap, (f2, h2, g2, s2))
                        generated += 1
    return None, INF, expanded, generated, ftrace, False


# --------------------------------------------------------------------------- post-processing


def _subgoal_indices(xy: FloatArray, modes: list[int], spacing: float) -> list[int]:
    """Indices of the waypoints that become subgoals: direction changes, spacing cuts, the goal."""
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


def _lengths(wp: FloatArray) -> tuple[float, float]:
    if len(wp) < 2:
        return 0.0, 0.0
    length = float(np.sum(np.linalg.norm(np.diff(wp[:, :2], axis=0), axis=1)))
    turn = float(np.sum(np.abs(geometry.wrap_angle(np.diff(wp[:, 2])))))
    return length, turn


# --------------------------------------------------------------------------- object route


def _manipulation_bound(
    cspace: ObjectCSpace, goal_cell: tuple[int, int], manip: float
) -> list[list[float]]:
    """Per mode, per padded (x, y) cell: a lower bound (s) on the manipulation cost still to pay.

    Translation mode d: ``manip`` times the fewest direction changes when the last move was d
    (:func:`controller.heuristics.turn_bounds` over the projected free space). Rotating: one
    change to start translating again, plus the fewest changes after it, unless already at the
    goal cell. Start: the fewest changes with the first direction free. Each mode change is
    charged ``manip`` and every change of translation direction needs at least one, so the
    bound is admissible.
    """
    fr = cspace.frame
    w, hh = fr.nx + 2, fr.ny + 2
    out: list[list[float]] = []
    if manip <= 0:
        zero = [0.0] * (w * hh)
        return [zero] * N_MODES
    t, v = heuristics.turn_bounds(cspace.free.any(axis=0), goal_cell, MOVES_8)
    rot = 1.0 + v
    rot[goal_cell] = 0.0
    for layer_val in [*t, rot, v]:
        pad = np.full((hh, w), INF)
        pad[1:-1, 1:-1] = manip * layer_val
        out.append(pad.ravel().tolist())
    return out


def object_heuristic(cspace: ObjectCSpace, kind: str, goal_cell: tuple[int, int]) -> FloatArray:
    """The named heuristic's (x, y) distance table (m) over the projected free space.

    The projected free space holds the cells free at one heading at least; see
    :mod:`controller.heuristics` for which tables are admissible.
    """
    free2d = cspace.free.any(axis=0)
    return heuristics.heuristic_table(kind, free2d, goal_cell, cspace.frame.resolution)


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
    h_table: FloatArray | None = None,
    pathmax: bool = True,
    turn_bound: bool = True,
    max_expanded: int = 20_000_000,
    trace: bool = False,
) -> RouteResult:
    """Plan the carried object's route from ``start`` to ``goal`` poses (x m, y m, theta rad).

    bounds [[xmin, ymin], [xmax, ymax]] (m); obstacles: world polygons (n, 2); footprint_polygon:
    the object polygon in its frame (CCW, m); robot_radius: the fleet's largest robot radius (m);
    params: the [route] section (resolution, heading_bins, heuristic, wg, wh, speed, yaw_rate,
    manipulation_cost, subgoal_spacing). ``cspace`` reuses a C-space from
    :func:`build_object_cspace` (then bounds, obstacles, footprint and radius are not used);
    ``h_table`` reuses an (x, y) heuristic table (m) from :func:`object_heuristic` for this goal.
    ``pathmax=False`` turns Eq. 2 off (for tests); ``turn_bound=False`` drops the manipulation
    bound from h (the bare paper potentials); ``trace`` records f of each expansion.
    Never raises for an unreachable goal: the result's status is "no_path" with a reason.
    """
    kind, wg, wh = params.heuristic, float(params.wg), float(params.wh)
    _check_weights(wg, wh)
    if kind not in heuristics.HEURISTICS:
        raise ValueError(f"heuristic: expected one of {heuristics.HEURISTICS}, got {kind!r}")
    if cspace is None:
        cspace = build_object_cspace(
            bounds,
            obstacles,
            footprint_polygon,
            robot_radius,
            params.resolution,
            params.heading_bins,
        )
    elif (
        abs(cspace.frame.resolution - params.resolution) > 1e-12
        or cspace.heading_bins != params.heading_bins
    ):
        raise ValueError(
            "cspace: built at resolution "
            f"{cspace.frame.resolution} m / {cspace.heading_bins} headings, params ask for "
            f"{params.resolution} m / {params.heading_bins}"
        )
    start_p = np.asarray(start, dtype=float)[:3]
    goal_p = np.asarray(goal, dtype=float)[:3]
    sc, gc = cspace.cell_of(start_p), cspace.cell_of(goal_p)
    for name, cell in (("start", sc), ("goal", gc)):
        if cell is None:
            return _no_path(f"{name} lies outside the world bounds", kind, wg, wh)
        if cspace.occupied[cell]:
            return _no_path(
                f"{name} pose collides: the footprint grown by the robots hits an obstacle or a "
                "wall there",
                kind,
                wg,
                wh,
            )
    assert sc is not None and gc is not None
    if cspace.labels[sc] != cspace.labels[gc]:
        return _no_path(
            "goal unreachable: start and goal lie in different free regions of the C-space",
            kind,
            wg,
            wh,
        )
    fr = cspace.frame
    k_bins = cspace.heading_bins
    if h_table is None:
        h_table = object_heuristic(cspace, kind, (gc[1], gc[2]))
    w, hh = fr.nx + 2, fr.ny + 2
    layer = w * hh
    free3 = np.zeros((k_bins, hh, w), dtype=np.uint8)
    free3[:, 1:-1, 1:-1] = cspace.free
    hxy = np.full((hh, w), INF)
    hxy[1:-1, 1:-1] = np.asarray(h_table, dtype=float) / params.speed
    step = 2.0 * math.pi / k_bins
    dk = np.abs(np.arange(k_bins) - gc[0])
    dk = np.minimum(dk, k_bins - dk)
    hth = dk * step / params.yaw_rate
    h3 = hth[:, None, None] + hxy[None]
    h3[free3 == 0] = INF
    h = h3.ravel().tolist()
    toff = [int(dy * w + dx) for dx, dy in MOVES_8]
    tcost = [fr.resolution * math.hypot(dx, dy) / params.speed for dx, dy in MOVES_8]
    start_c = sc[0] * layer + (sc[1] + 1) * w + sc[2] + 1
    goal_c = gc[0] * layer + (gc[1] + 1) * w + gc[2] + 1
    hmode = _manipulation_bound(
        cspace, (gc[1], gc[2]), params.manipulation_cost if turn_bound else 0.0
    )
    path, cost, expanded, generated, ftrace, limited = _search_object(
        h,
        hmode,
        layer,
        k_bins,
        toff,
        tcost,
        step / params.yaw_rate,
        params.manipulation_cost,
        start_c,
        goal_c,
        wg,
        wh,
        pathmax,
        max_expanded,
        trace,
    )
    ft = np.asarray(ftrace, dtype=float)
    if path is None:
        reason = (
            f"expansion limit of {max_expanded} nodes reached"
            if limited
            else "search exhausted: goal unreachable"
        )
        return _no_path(reason, kind, wg, wh, expanded=expanded, generated=generated, f_trace=ft)
    st = np.asarray(path, dtype=np.int64)
    c, modes = np.divmod(st, N_MODES)
    k, p = np.divmod(c, layer)
    iy, ix = np.divmod(p, w)
    xs = fr.x0 + (ix - 1 + 0.5) * fr.resolution
    ys = fr.y0 + (iy - 1 + 0.5) * fr.resolution
    th = geometry.wrap_angle(k * step)
    wp = np.stack([xs, ys, np.atleast_1d(th)], axis=1)
    wp[0] = start_p
    if len(wp) > 1:
        wp[-1] = goal_p
    else:
        wp = np.vstack([start_p, goal_p])
        modes = np.array([MODE_START, MODE_START])
    mode_list = modes.tolist()
    idx = _subgoal_indices(wp[:, :2], mode_list, params.subgoal_spacing)
    manip = sum(
        1
        for a, b in zip(mode_list[1:-1], mode_list[2:], strict=True)
        if a != b and not (a == MODE_ROTATE and b == MODE_ROTATE)
    )
    length, turn = _lengths(wp)
    return RouteResult(
        status="ok",
        waypoints=wp,
        subgoals=wp[idx],
        cost=float(cost),
        length_m=length,
        rotation_rad=turn,
        manipulations=manip,
        expanded=expanded,
        generated=generated,
        heuristic=kind,
        wg=wg,
        wh=wh,
        f_trace=ft,
    )


# --------------------------------------------------------------------------- robot routes


# --------------------------------------------------------------------------- shipped maps
