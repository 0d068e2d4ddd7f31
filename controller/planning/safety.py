"""Safety filter: a control-barrier-function QP (osqp) over all robots' world velocities.

Decision variable u (2N,), world-frame velocities (m/s). Minimise |u - u_nom|^2 subject to:

- robot-robot: 2 d_ij . (u_i - u_j) >= -gamma * h_ij, h_ij = |d_ij|^2 - (r_i + r_j + margin)^2;
  two robots both at the object (``close``) keep ``close_margin`` instead (the capture plan's
  spacing of contact robots: contacts in a concave notch are nearer each other than ``margin``);
- robot-polygon (obstacles, the object, stale robots as discs): n . u_i >= -gamma * (dist - r -
  margin), n the outward direction from the polygon's closest point;
- world bounds and speed: a box on each component (the walls and ``max_speed``) and the two
  diagonals, ``|u_x ± u_y| / √2 ≤ max_speed``: an octagon around the speed disc, so a robot
  keeps at least its full speed in every direction (a box of ``max_speed / √2`` would cut it to
  71 % along the axes); the tracking law and the agent clamp the 8 % the corners exceed.

The sparsity pattern is built once for N robots and P polygons; each call only updates values
(``Ax``, ``q``, ``l``, ``u``) and warm-starts. Differential robots are filtered as single
integrators at their centre (the mission turns the filtered velocity into (v, wz), driving
forwards or backwards along its axis); the look-ahead-point model for them is not done yet.
If the QP is infeasible while some robots are already inside a margin (to each other, or to
a polygon they are not closing in on: squeezed between the object and a wall, say), with
``relax``, those violated rows are relaxed to "no closer" and the QP solved again (status
``relaxed``: the robot moves away or slides out along the tangent; ``Rows.relaxations``). If
it is still infeasible (or osqp fails), the robots whose constraints are already violated
stop, the others keep their nominal velocity (speed-capped), and the status says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import osqp
from scipy import sparse

from controller import geometry

INF = 1e20
MAX_ITER = 2000  # osqp's iterations for one solve
# a solve that stops at MAX_ITER goes on from its last iterate this many times longer before it
# counts as failed: ADMM near its limit ends on either side of it with the input's last bits
# (numpy's SIMD kernels), so the same log once replayed "relaxed" on one CPU and "every robot
# stopped" on another
MORE_ITER = 4
# robot pairs above which the QP keeps only the pairs that can bind (about 17 robots): below,
# every pair's row (the golden logs' fleets of 6 replay unchanged); above, the pair rows
# (N²/2: 4 950 at 100 robots) made osqp most of the lab tick
PRUNE_PAIRS = 128


def _solved(res) -> bool:
    return (
        res.x is not None
        and str(res.info.status).startswith("solved")
        and bool(np.all(np.isfinite(res.x)))
    )


@dataclass
class FilterResult:
    """Filtered world velocities (N, 2), status, robots stopped because infeasible."""

    velocities: np.ndarray
    status: str
    stopped: np.ndarray
    changed: float
    aim: np.ndarray | None = None  # (N, 2): the free solution (differential robots turn to it)


@dataclass
class Rows:
    """The barrier rows' lower bounds of one call, for the relaxation: ``pair`` (pairs,),
    ``poly`` (N, P) and ``moving`` (N, P), the share of ``poly`` that is the polygon's own
    motion; ``squeezed`` (N, P) the polygon rows a robot may relax; ``relax`` whether to."""

    pair: np.ndarray
    poly: np.ndarray
    moving: np.ndarray
    squeezed: np.ndarray
    relax: bool

    def relaxations(self, lo: np.ndarray) -> list[np.ndarray]:
        """The lower bounds to try in turn when the QP is infeasible with robots already
        inside a margin (recovering at gamma is impossible for them):

        1. the violated rows ask "no closer" only: a pair's distance may not shrink; a robot
           squeezed by a moving polygon keeps its distance to it (moves with it or away);
        2. as 1, but a squeezed robot need not give way to the polygon's motion (it may not
           move toward it; the object pushed into it along a wall, it slides out along the
           tangent instead of freezing).

        Relaxing beats stopping: a robot the filter stops can still be pushed, by the object
        it stands in the way of, into the robot beside it (two robots stopped in a lab's
        carry were pushed together by the crate). Empty without ``relax`` or violated rows."""
        pair_bad = self.pair > 0
        if not self.relax or not (pair_bad.any() or self.squeezed.any()):
            return []
        k = len(self.pair)
        floors = [self.moving]
        if np.any(self.moving[self.squeezed] > 0):  # else the second is the first
            floors.append(np.minimum(self.moving, 0.0))
        out = []
        for poly_floor in floors:
            relaxed = lo.copy()
            relaxed[:k][pair_bad] = 0.0
            poly = relaxed[k : k + self.poly.size].reshape(self.poly.shape)
            poly[self.squeezed] = poly_floor[self.squeezed]
            out.append(relaxed)
        return out


@dataclass
class SafetyFilter:
    """Vectorised, warm-started CBF filter for N robots among ``n_polygons`` polygons."""

    radii: np.ndarray
    max_speed: np.ndarray
    bounds: np.ndarray  # [[xmin, ymin], [xmax, ymax]]
    n_polygons: int
    margin: float = 0.05
    gamma: float = 4.0
    warm: bool = True
    axial: np.ndarray | None = None  # (N,) bool: differential robots (they move along their axis)
    close_margin: float | None = None  # m between two ``close`` robots (None: ``margin``)
    prune: bool | None = None  # only the pairs that can bind (None: above PRUNE_PAIRS pairs)
    _prob: osqp.OSQP | None = field(default=None, repr=False)
    _perm: np.ndarray | None = field(default=None, repr=False)
    _kept_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int), repr=False)
    _last: np.ndarray | None = field(default=None, repr=False)  # the last solution (warm start)

    def __post_init__(self) -> None:
        n = len(self.radii)
        self.n = n
        self.axial = np.zeros(n, bool) if self.axial is None else np.asarray(self.axial, bool)
        self._all_i, self._all_j = np.triu_indices(n, 1)
        # a large fleet's QP holds only the pairs that can bind (``_pairs_for``)
        if self.prune is None:
            self.prune = len(self._all_i) > PRUNE_PAIRS
        if self.prune:  # no pair until one can bind
            self._layout(self._all_i[:0], self._all_j[:0])
        else:
            self._layout(self._all_i, self._all_j)

    def _layout(self, iu: np.ndarray, ju: np.ndarray) -> None:
        """The constraint matrix's rows and sparsity pattern for the robot pairs ``iu``, ``ju``
        (row layout: pairs, robot x polygon, box (2N), diagonals (2N), axes (N))."""
        n = self.n
        self.pi, self.pj = iu, ju
        npair = len(iu)
        rows, cols = [], []
        r = np.arange(npair)
        for k in range(2):
            rows += [r, r]
            cols += [2 * iu + k, 2 * ju + k]
        rp = npair + np.arange(n * self.n_polygons)
        ri = np.repeat(np.arange(n), self.n_polygons)
        for k in range(2):
            rows.append(rp)
            cols.append(2 * ri + k)
        rb = npair + n * self.n_polygons + np.arange(2 * n)
        rows.append(rb)
        cols.append(np.arange(2 * n))
        rd = npair + n * self.n_polygons + 2 * n + np.arange(2 * n)  # diagonals: 2 per robot
        for k in range(2):
            rows.append(rd)
            cols.append(2 * np.repeat(np.arange(n), 2) + k)
        ra = npair + n * self.n_polygons + 4 * n + np.arange(n)  # axis rows: 1 per robot
        for k in range(2):
            rows.append(ra)
            cols.append(2 * np.arange(n) + k)
        self._rows = np.concatenate(rows)
        self._cols = np.concatenate(cols)
        self.m = npair + n * self.n_polygons + 5 * n
        self._box = slice(npair + n * self.n_polygons, npair + n * self.n_polygons + 4 * n)
        self._axis = slice(self.m - n, self.m)
        tag = sparse.csc_matrix(
            (np.arange(1, len(self._rows) + 1, dtype=float), (self._rows, self._cols)),
            shape=(self.m, 2 * n),
        )
        self._perm = tag.data.astype(int) - 1  # csc data order -> our COO order
        self._pattern = tag
        self.ri = ri
        self._prob = None  # a new pattern: set up again at the next call

    def _pairs_for(self, p: np.ndarray, close: np.ndarray | None) -> None:
        """Keep in the QP every pair whose row can bind at positions ``p``: the others hold
        for any velocities in the speed octagon (|u| ≤ √2 max_speed), since
        2 d·(u_i − u_j) ≥ −2|d| √2 (v_i + v_j) ≥ −γh, so leaving them out changes neither the
        feasible set nor the solution. The kept set has slack (pairs up to twice that reach)
        and is rebuilt only when a pair that can bind is missing from it."""
        d = p[self._all_i] - p[self._all_j]
        dist = np.sqrt(np.sum(d * d, axis=1))
        margin = self._pair_margin(close, self._all_i, self._all_j)
        h = dist**2 - (self.radii[self._all_i] + self.radii[self._all_j] + margin) ** 2
        reach = (
            2.0 * np.sqrt(2.0) * dist * (self.max_speed[self._all_i] + self.max_speed[self._all_j])
        )
        need = self.gamma * h < reach * (1.0 + 1e-6)
        kept = np.zeros(len(self._all_i), bool)
        kept[self._kept_index] = True
        if not np.all(kept[need]):
            index = np.flatnonzero(self.gamma * h < 2.0 * reach)
            self._kept_index = index
            self._layout(self._all_i[index], self._all_j[index])

    def _setup(self, ax: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        a = self._pattern.copy()
        a.data = ax[self._perm]
        p = sparse.identity(2 * self.n, format="csc")
        self._prob = osqp.OSQP()
        self._prob.setup(
            P=sparse.triu(p, format="csc"),
            q=q,
            A=a,
            l=lo,
            u=hi,
            verbose=False,
            polishing=False,
            warm_starting=True,
            eps_abs=1e-4,
            eps_rel=1e-4,
            max_iter=MAX_ITER,
        )

    def filter(
        self,
        positions: np.ndarray,
        u_nom: np.ndarray,
        polygons: list[np.ndarray],
        exempt: np.ndarray | None = None,
        stale: np.ndarray | None = None,
        motion: list | None = None,
        overlap: np.ndarray | None = None,
        hold: np.ndarray | None = None,
        relax: bool = True,
        headings: np.ndarray | None = None,
        close: np.ndarray | None = None,
    ) -> FilterResult:
        """Filter nominal world velocities (N, 2) at robot centres (N, 2).

        ``polygons`` (at most ``n_polygons``) are obstacles and the object, world frame;
        ``exempt`` (N, P) bool relaxes a robot-polygon constraint to touching (a robot closing
        in on its own contact point: margin 0, never inside); ``stale`` robots are held at zero
        and the others avoid them. ``motion`` (one entry per polygon, None for static ones)
        gives a moving polygon's (vx, vy, wz) about its centroid: its barrier then holds
        relative to that motion. ``overlap`` (N,) m lets an exempt robot's disc overlap the
        polygon's estimate by that much (a robot preloading its contact pushes into it; the
        physics stops it at the surface, the estimates may overlap by their noise). ``hold``
        (N,) robots hold their ground against moving polygons: their barrier ignores the
        polygon's motion (a robot caging the object must not yield to its push). ``headings``
        (N,) rad: with them, the ``axial`` (differential) robots' velocities come out along
        their axes (``aim`` holds the free solution they turn toward); without, every robot
        is filtered as a point that moves any way. ``close`` (N,) robots at the object: a pair
        of them keeps ``close_margin`` (when smaller than ``margin``) between their discs.
        """
        n, npoly = self.n, self.n_polygons
        stale = np.zeros(n, bool) if stale is None else np.asarray(stale, bool)
        u_nom = np.where(stale[:, None], 0.0, u_nom)
        p = positions
        if self.prune:
            self._pairs_for(p, close)
        # robot pairs
        d = p[self.pi] - p[self.pj]
        rs = self.radii[self.pi] + self.radii[self.pj] + self._pair_margin(close, self.pi, self.pj)
        h = np.sum(d * d, axis=1) - rs**2
        vals = [2 * d[:, 0], -2 * d[:, 0], 2 * d[:, 1], -2 * d[:, 1]]
        lo_pair = -self.gamma * h
        # polygons
        nrm = np.zeros((n, npoly, 2))
        lo_poly = np.full((n, npoly), -INF)
        moving = np.zeros((n, npoly))  # each row's share of the polygon's own motion
        for k, poly in enumerate(polygons[:npoly]):
            a = poly
            b = np.roll(poly, -1, axis=0)
            dist, closest = geometry.point_segment_distance(p, a, b)
            j = np.argmin(dist, axis=1)
            c = closest[np.arange(n), j]
            vec = p - c
            dd = np.maximum(np.linalg.norm(vec, axis=1), 1e-9)
            inside = geometry.points_in_polygon(p, poly)
            sd = np.where(inside, -dd, dd)
            nv = vec / dd[:, None] * np.where(inside, -1.0, 1.0)[:, None]
            nrm[:, k] = nv
            # an exempt robot (closing in on its own contact point) may touch the polygon but
            # not enter it: margin 0 instead of the safety margin
            margin = self.margin
            if exempt is not None:
                touch = 0.0 if overlap is None else -np.asarray(overlap, float)
                margin = np.where(exempt[:, k], touch, self.margin)
            lo_poly[:, k] = -self.gamma * (sd - self.radii - margin)
            if motion is not None and k < len(motion) and motion[k] is not None:
                vx, vy, wz = (float(v) for v in motion[k])
                rel = c - geometry.centroid(poly)
                v_c = np.stack([vx - wz * rel[:, 1], vy + wz * rel[:, 0]], 1)
                relative = np.sum(nv * v_c, axis=1)  # ∇h·(v_i − v_poly) ≥ −γh
                if hold is not None:
                    relative = np.where(hold, 0.0, relative)
                lo_poly[:, k] += relative
                moving[:, k] = relative
        # a robot held at zero (stale, or held by the plan) keeps no barrier of its own: its
        # velocity is fixed, so a row of its inside a margin could only make the whole QP
        # infeasible (a held robot 4 cm from the object froze every mover of a re-arrangement
        # for 200 s in a lab run); the others keep their barriers to it (pair rows stay), and
        # a pair of two held robots has nothing to solve
        lo_poly[stale] = -INF
        lo_pair = np.where(stale[self.pi] & stale[self.pj], -INF, lo_pair)
        flat = nrm.reshape(-1, 2)
        vals += [flat[:, 0], flat[:, 1]]
        vals.append(np.ones(2 * n))
        h = np.sqrt(0.5)
        vals += [np.full(2 * n, h), np.tile([h, -h], n)]  # diagonals (u_x ± u_y) / √2
        axial = self.axial & ~stale if headings is not None else np.zeros(n, bool)
        th = np.zeros(n) if headings is None else np.asarray(headings, float)
        vals += [np.where(axial, -np.sin(th), 0.0), np.where(axial, np.cos(th), 0.0)]
        ax = np.concatenate(vals)
        # box: speed and world bounds (stay in by gamma * distance to the wall)
        vmax = np.repeat(self.max_speed, 2)
        lo_b = -vmax.copy()
        hi_b = vmax.copy()
        (x0, y0), (x1, y1) = self.bounds
        rr = np.repeat(self.radii + self.margin, 2)
        pf = p.reshape(-1)
        lowwall = np.tile([x0, y0], n) + rr
        highwall = np.tile([x1, y1], n) - rr
        lo_b = np.maximum(lo_b, np.minimum(-self.gamma * (pf - lowwall), 0.0))
        hi_b = np.minimum(hi_b, np.maximum(self.gamma * (highwall - pf), 0.0))
        st = np.repeat(stale, 2)
        lo_b[st] = 0.0
        hi_b[st] = 0.0
        diag = vmax.copy()
        diag[st] = 0.0
        # stale robots: others see them as fixed; the pair row stays (u_stale = 0)
        free = np.full(n, INF)
        lo = np.concatenate([lo_pair, lo_poly.reshape(-1), lo_b, -diag, -free])
        hi = np.concatenate([np.full(len(lo_pair) + n * npoly, INF), hi_b, diag, free])
        lo = np.minimum(lo, hi)
        q = -u_nom.reshape(-1).astype(float)
        if self._prob is None or not self.warm:
            self._setup(ax, q, lo, hi)
            if self.warm and self._last is not None:
                self._prob.warm_start(x=self._last)  # a pattern rebuilt: start from the last
        else:
            self._prob.update(q=q, l=lo, u=hi, Ax=ax[self._perm])
        # rows a squeezed robot may relax: inside its margin to a polygon it is not closing
        # in on (a robot in contact with the object stops as before), and robot pairs inside
        # their margin
        squeezed = lo_poly > 0
        if exempt is not None:
            squeezed &= ~np.asarray(exempt, bool)[:, : lo_poly.shape[1]]
        rows = Rows(lo_pair, lo_poly, moving, squeezed, relax)
        u, status, stopped = self._solve(lo, hi, rows, np.zeros(n, bool), fresh=True)
        aim = None
        if axial.any():
            # again with the differential robots on their axes: the velocity each one drives
            # toward the free solution's share along the axis, shrunk the more it is askew (a
            # robot turning toward its aim creeps, it does not sweep sideways at speed)
            aim = u
            along = np.cos(th) * u[:, 0] + np.sin(th) * u[:, 1]
            askew = np.abs(along) / np.maximum(np.linalg.norm(u, axis=1), 1e-12)
            target = np.where(axial[:, None], u * askew[:, None], u_nom)
            self._prob.update(q=-target.reshape(-1))
            lo[self._axis] = np.where(axial, 0.0, -INF)
            hi[self._axis] = np.where(axial, 0.0, INF)
            u, status2, stopped = self._solve(lo, hi, rows, stopped, fresh=False)
            status = status if status2.startswith("solved") else status2
        u = np.where(stale[:, None], 0.0, u)
        self._last = u.reshape(-1).copy()
        return FilterResult(u, status, stopped, float(np.abs(u - u_nom).max()), aim)

    def _pair_margin(
        self, close: np.ndarray | None, pi: np.ndarray, pj: np.ndarray
    ) -> np.ndarray | float:
        """Each pair's margin: ``close_margin`` for two ``close`` robots, else ``margin``."""
        if close is None or self.close_margin is None:
            return self.margin
        both = np.asarray(close, bool)[pi] & np.asarray(close, bool)[pj]
        return np.where(both, min(self.margin, self.close_margin), self.margin)

    def _run(self) -> Any:
        """osqp's solve; one that stopped at its iteration limit goes on from where it stopped
        (``MORE_ITER`` × longer) before its answer counts."""
        res = self._prob.solve(raise_error=False)
        if str(res.info.status).startswith("maximum iterations"):
            self._prob.update_settings(max_iter=MORE_ITER * MAX_ITER)
            res = self._prob.solve(raise_error=False)
            self._prob.update_settings(max_iter=MAX_ITER)
        return res

    def _solve(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        rows: Rows,
        stopped: np.ndarray,
        fresh: bool,
    ) -> tuple[np.ndarray, str, np.ndarray]:
        """Solve with bounds ``lo``/``hi``; if infeasible, relax the rows already violated
        (``Rows.relaxations``), then stop the robots concerned and solve for the others.
        Velocities (N, 2), status, robots stopped."""
        n = self.n
        if stopped.any():
            return self._without(lo, hi, rows.pair, rows.poly, stopped, "infeasible")
        if not fresh:
            self._prob.update(l=lo, u=hi)
        res = self._run()
        status = str(res.info.status)
        for relaxed in rows.relaxations(lo) if not _solved(res) else ():
            self._prob.update(l=relaxed)
            res = self._run()
            if _solved(res):
                status = "relaxed"
                break
            status = str(res.info.status)
        if _solved(res):
            return res.x.reshape(n, 2), status, np.zeros(n, bool)
        # infeasible: the robots whose constraints are violated stop
        return self._without(
            lo, hi, rows.pair, rows.poly, self._concerned(rows.pair, rows.poly), status
        )

    def _without(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        lo_pair: np.ndarray,
        lo_poly: np.ndarray,
        stopped: np.ndarray,
        status: str,
    ) -> tuple[np.ndarray, str, np.ndarray]:
        """The robots ``stopped`` held at zero, the others filtered round them. Violated rows
        ask "no closer", so standing still is always feasible; if osqp still fails, every
        robot stops."""
        n = self.n
        lo2, hi2 = lo.copy(), hi.copy()
        k = len(lo_pair) + lo_poly.size
        lo2[:k] = np.minimum(lo2[:k], 0.0)
        held = np.repeat(stopped, 2)
        box = lo2[self._box]  # views: the box rows, then the diagonals
        box_hi = hi2[self._box]
        box[: 2 * n][held] = 0.0
        box_hi[: 2 * n][held] = 0.0
        box[2 * n :][held] = 0.0
        box_hi[2 * n :][held] = 0.0
        self._prob.update(l=lo2, u=hi2)
        res = self._run()
        if not _solved(res):
            # warm-started from an infeasible solve's iterates, ADMM can stall (max_iter) on a
            # problem that standing still makes feasible: once more from rest before stopping all
            self._prob.warm_start(x=np.zeros(2 * n), y=np.zeros(self.m))
            res = self._run()
        if not _solved(res):
            return np.zeros((n, 2)), status, np.ones(n, bool)
        u = res.x.reshape(n, 2)
        return np.where(stopped[:, None], 0.0, u), status, stopped

    def _concerned(self, lo_pair: np.ndarray, lo_poly: np.ndarray) -> np.ndarray:
        bad = np.zeros(self.n, bool)
        viol = lo_pair > 0
        bad[self.pi[viol]] = True
        bad[self.pj[viol]] = True
        bad |= np.any(lo_poly > 0, axis=1)
        if not bad.any():
            bad[:] = True
        return bad
