"""A single robot's global route on its disc C-space (the approach planner's detours).

Weighted A* with pathmax (Yamashita et al. Eq. 1-2; the search loop is
:func:`controller.planning.route.weighted_astar`, shared with the object's route) over an
8-connected 2-D grid. Pure: arrays in, a :class:`controller.planning.route.RouteResult` out.
Moves cost distance / ``speed`` (s).

The default heuristic ``"landmarks"`` is the octile distance (the exact cost of 8-connected
moves on an empty grid) tightened by landmark lower bounds (ALT, Goldberg & Harrelson 2005): the
grid distances from a few landmarks, computed once per roadmap (scipy csgraph), bound the
distance between any two cells by the triangle inequality, ``d(n, g) >= |d(L, g) - d(L, n)|``.
The larger of the two is admissible and consistent, and around obstacles much tighter than the
octile distance alone (``"octile"``), so the search expands far fewer cells.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from controller.planning import heuristics
from controller.planning.cspace import MOVES_8, RobotCSpace, build_robot_cspace
from controller.planning.route import (
    INF,
    FloatArray,
    RouteResult,
    _check_weights,
    _lengths,
    _no_path,
    ok_result,
    reopens,
    weighted_astar,
)

#: The robot search's heuristics: octile + landmarks (the default), octile, the paper's potentials.
ROBOT_HEURISTICS = ("landmarks", "octile", *heuristics.POTENTIALS)


class RobotRoadmap:
    """A robot disc's 2-D C-space prepared once for many searches (the approach planner's use).

    Holds the padded free mask, the move table and the landmark distances (``landmarks`` of
    them, spread by farthest-point selection); :meth:`plan` runs one search.
    Heuristics: "landmarks" (the default) and "octile" (admissible and consistent), "euclid"
    (admissible), "wavefront" (exact, admissible), "skeleton" (not).
    Moves cost distance / ``speed`` (s); there is no manipulation cost for a lone robot.
    """

    def __init__(self, cspace: RobotCSpace, speed: float = 1.0, landmarks: int = 4):
        if not speed > 0:
            raise ValueError(f"speed: expected > 0 m/s, got {speed!r}")
        self.cspace = cspace
        self.speed = float(speed)
        fr = cspace.frame
        self._w = fr.nx + 2
        pad = np.zeros((fr.ny + 2, fr.nx + 2), dtype=np.uint8)
        pad[1:-1, 1:-1] = ~cspace.occupied
        self._free = pad.astype(bool)
        self._moves = [
            (int(dy * self._w + dx), fr.resolution * math.hypot(dx, dy) / self.speed)
            for dx, dy in MOVES_8
        ]
        self._landmarks = heuristics.landmark_distances(~cspace.occupied, landmarks, fr.resolution)

    @staticmethod
    def build(
        bounds: ArrayLike,
        obstacles: list[ArrayLike],
        radius: float,
        resolution: float,
        speed: float = 1.0,
    ) -> RobotRoadmap:
        """Build the disc C-space (see :func:`controller.cspace.build_robot_cspace`) and wrap it."""
        return RobotRoadmap(build_robot_cspace(bounds, obstacles, radius, resolution), speed)

    def heuristic_table(self, kind: str, goal_cell: tuple[int, int]) -> FloatArray:
        """Distance table (m) for a goal cell (iy, ix)."""
        fr = self.cspace.frame
        if kind == "octile":
            return heuristics.octile((fr.ny, fr.nx), goal_cell, fr.resolution)
        if kind == "landmarks":
            table = heuristics.octile((fr.ny, fr.nx), goal_cell, fr.resolution)
            return heuristics.landmark_bound(self._landmarks, goal_cell, table)
        if kind not in ROBOT_HEURISTICS:
            raise ValueError(f"heuristic: expected one of {ROBOT_HEURISTICS}, got {kind!r}")
        return heuristics.heuristic_table(kind, ~self.cspace.occupied, goal_cell, fr.resolution)

    def plan(
        self,
        start_xy: ArrayLike,
        goal_xy: ArrayLike,
        *,
        heuristic: str = "landmarks",
        wg: float = 1.0,
        wh: float = 1.0,
        h_table: FloatArray | None = None,
        pathmax: bool = True,
        reopen: bool = False,
        max_expanded: int = 10_000_000,
        trace: bool = False,
        subgoal_spacing: float = 1.0,
    ) -> RouteResult:
        """Route from ``start_xy`` to ``goal_xy`` (m); waypoint headings follow the travel.

        ``h_table``: a distance table (m) for this goal (from :meth:`heuristic_table`);
        ``reopen``: re-open closed cells when ``wh > 1`` (see :func:`route.reopens`).
        """
        _check_weights(float(wg), float(wh))
        cs, fr = self.cspace, self.cspace.frame
        s_xy = np.asarray(start_xy, dtype=float)[:2]
        g_xy = np.asarray(goal_xy, dtype=float)[:2]
        sc, gc = fr.cell_of(s_xy), fr.cell_of(g_xy)
        for name, cell in (("start", sc), ("goal", gc)):
            if cell is None:
                return _no_path(f"{name} lies outside the world bounds", heuristic, wg, wh)
            if cs.occupied[cell]:
                return _no_path(
                    f"{name} collides: the robot disc there hits an obstacle or a wall",
                    heuristic,
                    wg,
                    wh,
                )
        assert sc is not None and gc is not None
        if cs.labels[sc] != cs.labels[gc]:
            return _no_path(
                "goal unreachable: start and goal lie in different free regions",
                heuristic,
                wg,
                wh,
            )
        w = self._w
        if h_table is None:
            h_table = self.heuristic_table(heuristic, gc)
        hpad = np.full((fr.ny + 2, w), INF)
        hpad[1:-1, 1:-1] = np.asarray(h_table, dtype=float) / self.speed
        start = (sc[0] + 1) * w + sc[1] + 1
        goal = (gc[0] + 1) * w + gc[1] + 1
        hpad[~self._free] = INF
        out = weighted_astar(
            start,
            goal,
            hpad.ravel().tolist(),
            self._moves,
            wg=float(wg),
            wh=float(wh),
            n_states=hpad.size,
            pathmax=pathmax,
            reopen=reopens(float(wg), float(wh), reopen),
            max_expanded=max_expanded,
            trace=trace,
        )
        counts = out.counts()
        if out.path is None:
            return _no_path(out.reason(max_expanded), heuristic, wg, wh, **counts)
        path, cost = out.path, out.cost
        iy, ix = np.divmod(np.asarray(path, dtype=np.int64), w)
        xy = np.stack(
            [fr.x0 + (ix - 0.5) * fr.resolution, fr.y0 + (iy - 0.5) * fr.resolution], axis=1
        )
        xy[0] = s_xy
        if len(xy) > 1:
            xy[-1] = g_xy
        else:
            xy = np.vstack([s_xy, g_xy])
        steps = np.diff(xy, axis=0)
        heading = np.arctan2(steps[:, 1], steps[:, 0]) if len(steps) else np.zeros(0)
        heading = np.r_[heading, heading[-1:]] if len(heading) else np.zeros(len(xy))
        wp = np.column_stack([xy, heading])
        dirs = np.diff(np.asarray(path, dtype=np.int64)).tolist()
        modes = [-1] + dirs + ([dirs[-1]] if dirs else [])
        modes = modes[: len(wp)]
        length, _ = _lengths(wp)
        return ok_result(wp, modes, subgoal_spacing, cost, length, 0, (heuristic, wg, wh), counts)


def plan_robot_route(
    bounds: ArrayLike,
    obstacles: list[ArrayLike],
    radius: float,
    start_xy: ArrayLike,
    goal_xy: ArrayLike,
    resolution: float,
    *,
    heuristic: str = "landmarks",
    wg: float = 1.0,
    wh: float = 1.0,
    speed: float = 1.0,
    roadmap: RobotRoadmap | None = None,
) -> RouteResult:
    """One robot's route (m) around static obstacles on its disc C-space; cost in seconds.

    Pass ``roadmap`` (a :class:`RobotRoadmap`) to reuse a C-space across calls; otherwise one is
    built from bounds, obstacles, radius (m) and resolution (m).
    """
    rm = roadmap or RobotRoadmap.build(bounds, obstacles, radius, resolution, speed)
    return rm.plan(start_xy, goal_xy, heuristic=heuristic, wg=wg, wh=wh)


def plan_detours(
    bounds: np.ndarray,
    obstacles: list,
    radius: float,
    resolution: float,
    starts: np.ndarray,
    goals: np.ndarray,
    spacing: float,
) -> list[list[np.ndarray]]:
    """The detour job (off the tick): a robot roadmap of the room for discs of ``radius`` and
    each robot's A* route from its start to its station, as waypoints (the station itself
    excluded: the approach takes over there); an empty list where no route is found."""
    rm = RobotRoadmap.build(bounds, obstacles, radius, resolution)
    out = []
    for start, goal in zip(starts, goals, strict=True):
        res = rm.plan(start, goal, subgoal_spacing=spacing)
        out.append([np.asarray(w[:2], float) for w in res.subgoals[:-1]] if res.ok else [])
    return out
