"""Braces for a fast object (issue 34, item 10): an object moving at ``approach.brace_share``
of the slowest robot's speed or faster is one the robots can hardly catch from behind. The
robots ahead of it wait in its path instead, at contact points that stop it: 2-4 of the GA's
candidate nodes whose frictionless contacts resist a push along its motion and ``SPREAD``
either side of it with no turn, with the least force (``brace_nodes``: a single brace, or a
set that only balances the push exactly, lets it slide past). They meet it together and,
touching, stand still (commanded exactly zero: their barrier holds its ground). The object's
drive cannot push robots that hold their ground, so it stops, and the rest of the fleet
closes in on an object at rest.

The braces are capture points: the job plans the capture set again with the brace nodes fixed
in it (``braced_capture``: the GA's points clear of them kept, reinforced until the set holds),
so no robot's contact lies beside a brace, and the braces stay where the set needs them
through close-in and hold. While robots brace, the job hands their points to no other robot.

``Braces`` keeps which points brace and where their robots wait, for one approach.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, linear_sum_assignment, milp

from controller import geometry
from controller.config import FleetConfig
from controller.mission.assign import COST_HORIZON_FACTOR, assign, interception_costs
from controller.mission.planners import Planners, PlanSlot
from controller.mission.types import FleetView
from controller.planning.approach import interception_times
from controller.planning.capture_set import CaptureSet, node_conflicts, reinforce_set
from controller.planning.hold import contact_wrenches

#: s before the object meets a brace: its meeting point stops following the prediction (a
#: robot that waits holds its ground; one that keeps adjusting is pushed)
FIX_S = 2.0
#: at most this many braces: the rest of the fleet approaches as before
MAX_BRACES = 4
#: N a brace's contact may carry per N of the object's push (a bound for the brace LP)
FORCE_CAP = 10.0
#: s between the job's looks for braces (each an LP over the candidate nodes and a
#: reinforcement)
BRACE_PERIOD = 0.5
#: s the object's estimate must stay that fast before the job looks (a filter's first
#: estimates of a slow object can be fast for a tick or two)
CONFIRM_S = 1.0
#: rad either side of the object's motion the braces also resist (a brace set that only
#: balances the push exactly lets an object that turns a little slide past)
SPREAD = 0.3


def brace_speed(cfg: FleetConfig, robots: np.ndarray) -> float:
    """m/s from which an object is braced: ``approach.brace_share`` of the slowest of the
    ``robots`` (N,) bool's max_speed (infinite: never, share 0 or no robot)."""
    speeds = [rb.max_speed for rb, ok in zip(cfg.robots, robots, strict=True) if ok]
    share = cfg.approach.brace_share
    return share * min(speeds) if share > 0 and speeds else float("inf")


def _clear_set(
    candidates: np.ndarray,
    normals: np.ndarray,
    centroid: np.ndarray,
    loads: np.ndarray,
    allowed: np.ndarray,
    conflict: np.ndarray,
) -> np.ndarray:
    """At most ``MAX_BRACES`` of the ``allowed`` nodes, no two in ``conflict``, that produce
    each of ``loads`` (L, 3) with the least sum of their largest forces: a mixed-integer LP (a
    capacity c_i per node, each load's forces within them, a node used or not). Empty when no
    such set produces the loads."""
    idx = np.flatnonzero(allowed)
    n, nl = len(idx), len(loads)
    if n == 0:
        return np.zeros(0, int)
    w = contact_wrenches(candidates[idx], normals[idx], centroid)
    # variables: capacities c (n), each load's forces f_k (L n), whether a node is used z (n)
    k = nl * n

    def row(c=None, f=None, z=None, m: int = n) -> np.ndarray:
        blocks = [np.zeros((m, n)) if c is None else c, np.zeros((m, k)) if f is None else f]
        return np.hstack(blocks + [np.zeros((m, n)) if z is None else z])

    eye, loads_flat = np.eye(n), np.ravel(loads)
    rows = [
        LinearConstraint(row(f=np.kron(np.eye(nl), w), m=3 * nl), loads_flat, loads_flat),
        LinearConstraint(row(c=np.tile(-eye, (nl, 1)), f=np.eye(k), m=k), -np.inf, 0.0),  # f ≤ c
        LinearConstraint(row(c=eye, z=-FORCE_CAP * eye), -np.inf, 0.0),  # c only if used
        LinearConstraint(row(z=np.ones((1, n)), m=1), 0, MAX_BRACES),
    ]
    pairs = np.argwhere(np.triu(conflict[np.ix_(idx, idx)], 1))
    if len(pairs):  # no two robot discs in conflict
        clash = np.zeros((len(pairs), n))
        clash[np.arange(len(pairs)), pairs[:, 0]] = 1
        clash[np.arange(len(pairs)), pairs[:, 1]] = 1
        rows.append(LinearConstraint(row(z=clash, m=len(pairs)), 0, 1))
    res = milp(
        np.r_[np.ones(n), np.zeros(k), 1e-3 * np.ones(n)],
        constraints=rows,
        integrality=np.r_[np.zeros(n + k), np.ones(n)],
        bounds=Bounds(0.0, np.r_[np.full(n + k, FORCE_CAP), np.ones(n)]),
    )
    if res.status != 0 or res.x is None:
        return np.zeros(0, int)
    used = res.x[n + k :] > 0.5
    return idx[used]


def brace_nodes(
    candidates: np.ndarray,
    normals: np.ndarray,
    centroid: np.ndarray,
    direction: np.ndarray,
    conflict: np.ndarray,
) -> np.ndarray:
    """Indices of candidate contact nodes (``candidates``, outward ``normals`` (K, 2), object
    frame, about ``centroid``) that brace an object pushed along ``direction`` (object frame):
    frictionless contacts that resist the push with no turn, and a push ``SPREAD`` either side
    of it, with the least force, clear of each other (``conflict``), none on a face the object
    moves away from more steeply than that (it would leave the brace behind). Empty when fewer
    than two do it (a single brace lets the object slide past) or more than ``MAX_BRACES``."""
    th = float(np.arctan2(direction[1], direction[0])) + np.array([0.0, -SPREAD, SPREAD])
    loads = -np.stack([np.cos(th), np.sin(th), np.zeros(3)], axis=1)  # pushing back
    # no face the object moves away from faster than a push SPREAD off its motion would
    ahead = normals @ np.array([np.cos(th[0]), np.sin(th[0])]) > -np.sin(SPREAD) - 1e-9
    pick = _clear_set(candidates, normals, centroid, loads, ahead, conflict)
    return pick if 2 <= len(pick) <= MAX_BRACES else np.zeros(0, int)


def braced_capture(
    cfg: FleetConfig, capture: CaptureSet, view: FleetView, available: np.ndarray
) -> tuple[CaptureSet, np.ndarray, np.ndarray] | None:
    """The capture set with braces for the object of ``view`` when it moves at
    ``brace_speed(cfg, available)`` or faster (None otherwise): the brace nodes
    (``brace_nodes``) fixed in it, the GA's points clear of them kept, reinforced until it
    holds ``capture.hold_force`` with the ``available`` robots; each brace's robot the one
    ahead of the object that meets it soonest (waiting on its path), the other points assigned
    as at the start. The set (its ``hold_capacity`` what it holds with the braces force-limited
    too: it may be below 1), which of its points brace (M,), and the assignment (M,); None when
    no brace set exists, no robot ahead meets one within the assignment's horizon, or the rest
    cannot hold the object even with the braces fixed."""
    ovel = np.zeros(2) if view.object_velocity is None else np.asarray(view.object_velocity)[:2]
    if float(np.hypot(*ovel)) < brace_speed(cfg, available):
        return None
    pose = np.asarray(view.object_pose, float)
    d = ovel / max(float(np.hypot(*ovel)), 1e-12)
    cand, nrm = capture.candidates, capture.candidate_normals
    centres = cand + cfg.max_robot_radius * nrm
    conflict, c = _conflict(cfg, capture)
    nodes = brace_nodes(cand, nrm, c, geometry.rot(float(pose[2])).T @ d, conflict)
    if len(nodes) == 0:
        return None
    mid = geometry.transform(c[None], pose)[0]
    robots = brace_robots(cfg, view, geometry.transform(centres[nodes], pose), mid, available)
    if robots is None:
        return None
    rows, cols = robots
    new = _set_around(cfg, capture, nodes, conflict, c, int(available.sum()))
    return None if new is None else _assigned(cfg, new, view, available, nodes[rows], cols)


def rebraced_capture(
    cfg: FleetConfig,
    capture: CaptureSet,
    view: FleetView,
    braces: np.ndarray,
    assignment: np.ndarray,
    available: np.ndarray,
    exclude: frozenset[int],
) -> tuple[CaptureSet, np.ndarray, np.ndarray] | None:
    """A braced capture (``braces`` (M,): its points that brace) planned again for a robot
    stuck on its way: the candidate nodes around the point it could not reach (``exclude``)
    left out, the braces and their robots kept, the rest around them as ``braced_capture``
    does. None when no set holds without those nodes."""
    nodes = np.asarray(capture.chosen, int)[braces]
    conflict, c = _conflict(cfg, capture)
    new = _set_around(cfg, capture, nodes, conflict, c, int(available.sum()), exclude)
    return None if new is None else _assigned(cfg, new, view, available, nodes, assignment[braces])


def _conflict(cfg: FleetConfig, capture: CaptureSet) -> tuple[np.ndarray, np.ndarray]:
    """(K, K) candidate nodes whose robot discs would be too close (as the GA has it), and the
    object's centroid."""
    conflict = node_conflicts(cfg, capture.candidates, capture.candidate_normals)
    return conflict, geometry.centroid(geometry.ensure_ccw(cfg.object_polygon()))


def _assigned(
    cfg: FleetConfig,
    new: CaptureSet,
    view: FleetView,
    available: np.ndarray,
    nodes: np.ndarray,
    robots: np.ndarray,
) -> tuple[CaptureSet, np.ndarray, np.ndarray]:
    """The set, which of its points brace (the ``nodes``), and its assignment: each brace node
    to its robot (``robots``, in the same order), the other points as at the start."""
    braces = np.isin(new.chosen, nodes)
    costs = interception_costs(cfg, new, view)
    big = 1e6 * (1.0 + costs.max(initial=0.0))
    for node, j in zip(nodes, robots, strict=True):  # the brace rows: their robot only
        row = int(np.flatnonzero(new.chosen == node)[0])
        costs[row] = big
        costs[row, j] = 0.0
        costs[~braces, j] = big  # and that robot for no other point
    return new, braces, assign(costs, available)


def _set_around(
    cfg: FleetConfig,
    capture: CaptureSet,
    nodes: np.ndarray,
    conflict: np.ndarray,
    centroid: np.ndarray,
    robots: int,
    exclude: frozenset[int] = frozenset(),
) -> CaptureSet | None:
    """The capture set of ``robots`` points with the brace ``nodes`` first: the rest planned
    around the braces with their contacts fixed in it (as walls are), then, the braces taken
    as the force-limited robots they are, the rest moved while that raises what the whole set
    holds (its ``hold_capacity``); never at the ``exclude`` nodes. None when the rest cannot
    hold it even with the braces fixed."""
    cand, nrm = capture.candidates, capture.candidate_normals
    free = ~conflict[:, nodes].any(axis=1)
    free[nodes] = False
    free[list(exclude)] = False  # nodes a robot could not get to
    rest = robots - len(nodes)
    keep = np.array([i for i in capture.chosen if free[i]], int)[: max(rest, 0)]
    fixed = contact_wrenches(cand[nodes], nrm[nodes], centroid)
    res = reinforce_set(cfg, cand, nrm, keep, free, fixed, robots=rest)
    if not res.holds:
        return None
    whole = reinforce_set(
        cfg, cand, nrm, np.r_[nodes, res.chosen].astype(int), free, robots=robots,
        locked=len(nodes),
    )  # fmt: skip
    chosen = whole.chosen
    return dataclasses.replace(
        capture,
        points=cand[chosen],
        normals=nrm[chosen],
        chosen=chosen,
        hold_capacity=whole.capacity if cfg.capture.hold_force > 0 else None,
        reinforced=res.added + whole.added,
    )


def brace_robots(
    cfg: FleetConfig, view: FleetView, touch: np.ndarray, mid: np.ndarray, available: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Which robot braces at each of the world contacts ``touch`` (K, 2) of the object of
    ``view`` (its centroid at ``mid``): (rows, robots), the ``available`` robots ahead of it
    that meet those contacts soonest, waiting on its path; None when some contact has no robot
    that meets it within the assignment's horizon."""
    ovel = np.asarray(view.object_velocity, float)[:2]
    xy = view.poses[:, :2]
    speed = np.array([rb.max_speed for rb in cfg.robots])
    horizon = max(cfg.approach.intercept_horizon, 1.0) * COST_HORIZON_FACTOR  # as assign's
    t = interception_times(xy, touch, np.broadcast_to(ovel, touch.shape), speed, horizon)
    t[:, ((xy - mid) @ ovel <= 0) | ~available] = horizon  # behind it, or away
    rows, cols = linear_sum_assignment(t)
    if len(rows) < len(touch) or (t[rows, cols] >= horizon).any():
        return None
    return rows, cols


@dataclass
class Braces:
    """Which capture points' robots brace (``on`` (M,)) and where each waits (``at`` (M, 2),
    world; NaN until the object is ``FIX_S`` away)."""

    m: int
    on: np.ndarray = field(init=False)
    at: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.on = np.zeros(self.m, bool)
        self.at = np.full((self.m, 2), np.nan)

    def any(self) -> bool:
        return bool(self.on.any())

    def meet(
        self, tgt: np.ndarray, vel: np.ndarray, t: np.ndarray, release: np.ndarray
    ) -> np.ndarray:
        """Goal positions (M, 2) for robots aimed at ``tgt`` moving with ``vel`` (M, 2), met
        after ``t`` (M,) s: the braces meet the object together (at the latest of their
        times), and wait at that point once it is ``FIX_S`` away. ``release`` (M,): braces
        that aim again (off the object it stopped, which may have turned as it stopped)."""
        t = np.asarray(t, float).copy()
        b = self.on
        t[b] = t[b].max(initial=0.0)
        goal = tgt + vel * t[:, None]
        self.at[release] = np.nan
        fix = b & np.isnan(self.at[:, 0]) & (t < FIX_S)
        self.at[fix] = goal[fix]
        held = b & ~np.isnan(self.at[:, 0])
        goal[held] = self.at[held]
        return goal

    def masks(
        self, n: int, assignment: np.ndarray, gap: np.ndarray, tolerance: float
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(N,) robots bracing (allowed to touch the object) and (N,) those of them touching
        it (within ``tolerance`` m of its surface: commanded exactly zero), or None where there
        are none."""
        touch = np.zeros(n, bool)
        touch[assignment[self.on]] = True
        still = np.zeros(n, bool)
        still[assignment[self.on & (gap < tolerance)]] = True
        return (touch if touch.any() else None), (still if still.any() else None)


class BraceWatch:
    """The job's look for braces during the approach, off the tick (a job of kind ``capture``
    on the planner port: the brace set is a mixed-integer LP of tens of ms), at most every
    ``BRACE_PERIOD`` s once the object has been fast for ``CONFIRM_S`` s without a break."""

    def __init__(self, planners: Planners) -> None:
        self.last_t = -np.inf
        self.job = PlanSlot(planners, "capture")
        self.asked_for: CaptureSet | None = None  # the capture set the pending look started from
        self.fast_since: float | None = None  # s: the object fast since, without a break

    def rebrace(self, cfg, capture, view, braces, assignment, available, exclude) -> None:
        """Ask for ``rebraced_capture`` (a robot stuck on its way while others brace)."""
        self.asked_for = capture
        self.job.request(
            view.t, rebraced_capture, cfg, capture, view, braces.copy(), assignment.copy(),
            available.copy(), frozenset(exclude),
        )  # fmt: skip

    def look(
        self,
        cfg: FleetConfig,
        capture: CaptureSet,
        view: FleetView,
        available: np.ndarray,
        bracing: bool = False,
    ) -> tuple[CaptureSet, np.ndarray, np.ndarray] | None:
        """A ``braced_capture`` (or ``rebraced_capture``) asked before, once it came, if the
        job's capture set is still the one it started from and its robots are all still
        ``available`` (N,); else None (and, unless robots brace already, a new one asked when
        it is time)."""
        got = self.job.take(view.t)
        if got is not None and got.ok and got.value is not None and capture is self.asked_for:
            if available[got.value[2]].all():  # no robot of it lost meanwhile
                return got.value
        ovel = view.object_velocity
        fast = ovel is not None and float(np.hypot(*ovel[:2])) >= brace_speed(cfg, available)
        if not fast or bracing:  # (robots that brace: only a re-plan for one stuck is asked)
            self.fast_since = None
            return None
        if self.fast_since is None:
            self.fast_since = view.t
        confirmed = view.t - self.fast_since >= CONFIRM_S
        if confirmed and not self.job.pending and view.t >= self.last_t + BRACE_PERIOD:
            self.last_t, self.asked_for = view.t, capture
            self.job.request(view.t, braced_capture, cfg, capture, view, available.copy())
        return None
