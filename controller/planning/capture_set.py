"""The capture set (pure): the GA's capture points (Sharma Eq. 3, ``planning.capture``)
reinforced until the contacts hold the object's push (``capture.hold_force``) with the robots'
force limits (``planning.hold``), and its re-plans: for an object pressed against walls
(``replan_pinned``) and for the robots left after a loss (``replan_for_robots``). The capture
job asks for the re-plans off the control tick (jobs of kind ``capture``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from controller import geometry
from controller.config import FleetConfig


class CapturePlanError(RuntimeError):
    """No capture set for this fleet (the message gives the planner's reason)."""


@dataclass(frozen=True)
class CaptureSet:
    """Contact points and their outward normals (M, 2), object frame, and what was checked;
    ``candidates``/``candidate_normals`` (K, 2) are the GA's nodes, ``chosen`` (M,) indices."""

    points: np.ndarray
    normals: np.ndarray
    objective: float
    form_closure: bool
    hold_capacity: float | None  # share of capture.hold_force the contacts resist (≥ 1 holds)
    reinforced: int  # points added to the GA's set so that it holds
    candidates: np.ndarray
    candidate_normals: np.ndarray
    chosen: np.ndarray
    walls: int = 0  # wall contacts the set counts on (an object pinned against a wall)


def plan_capture_set(
    cfg: FleetConfig, rng: np.random.Generator, max_robots: int | None = None
) -> CaptureSet:
    """The GA's capture points, reinforced to hold ``capture.hold_force`` (CapturePlanError when the
    GA finds no feasible plan, with its reason, or the fleet is too small to hold the object);
    ``max_robots``: the robots available (None: the fleet)."""
    from controller.planning.capture import plan_for_fleet

    plan = plan_for_fleet(cfg, rng, max_robots)
    if not plan.feasible:
        raise CapturePlanError(f"no feasible capture plan: {plan.reason}")
    chosen = np.asarray(plan.chosen, int)
    capacity, added = None, 0
    if cfg.capture.hold_force > 0:
        res = reinforce_set(cfg, plan.candidates, plan.normals, chosen, robots=max_robots)
        if not res.holds:
            raise CapturePlanError(_cannot_hold(cfg, res))
        chosen, capacity, added = res.chosen, res.capacity, res.added
    return CaptureSet(
        plan.candidates[chosen],
        plan.normals[chosen],
        float(plan.objective),
        bool(plan.form_closure),
        capacity,
        added,
        plan.candidates,
        plan.normals,
        chosen,
    )


def _cannot_hold(cfg: FleetConfig, res) -> str:
    weakest = min(rb.max_force for rb in cfg.robots)
    return (
        f"the fleet cannot hold the object: {len(res.chosen)} robots of max_force "
        f"{weakest:g} N resist {100 * res.capacity:.0f} % of capture.hold_force = "
        f"{cfg.capture.hold_force:g} N in the worst direction (more robots, stronger robots, "
        "or a lower hold_force)"
    )


def reinforce_set(
    cfg: FleetConfig,
    cand: np.ndarray,
    nrm: np.ndarray,
    chosen: np.ndarray,
    allowed: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    robots: int | None = None,
    locked: int = 0,
):
    """The GA's set reinforced to hold ``capture.hold_force`` (a set that only has to close the
    object, ``hold_force`` 0, is held to a token load), with at most ``robots`` points (None:
    the fleet); the first ``locked`` points of ``chosen`` stay."""
    from controller.planning.hold import reinforce

    c, load, weakest = _hold_load(cfg)
    conflict = node_conflicts(cfg, cand, nrm)
    ok = np.ones(len(cand), bool) if allowed is None else allowed
    n = len(cfg.robots) if robots is None else robots
    return reinforce(
        cand, nrm, c, chosen, ok, conflict, weakest, load, n, fixed=fixed, locked=locked
    )


def node_conflicts(
    cfg: FleetConfig, cand: np.ndarray, nrm: np.ndarray, spare: float = 0.0
) -> np.ndarray:
    """(K, K) candidate nodes (object frame, outward normals) whose robots' discs would be
    too close: nearer than two of the largest robot's radius plus the larger of
    ``capture.clearance`` and ``approach.safety_margin`` (as the GA has it) and ``spare`` m."""
    r = cfg.max_robot_radius
    centres = cand + r * nrm
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = d < 2 * r + max(cfg.capture.clearance, cfg.approach.safety_margin) + spare
    np.fill_diagonal(conflict, False)
    return conflict


def _hold_load(cfg: FleetConfig) -> tuple[np.ndarray, np.ndarray, float]:
    """The object's centroid, the disturbances a capture set must hold (``capture.hold_force``;
    a token load when 0) and the weakest robot's force."""
    from controller.planning.hold import disturbances

    poly = geometry.ensure_ccw(cfg.object_polygon())
    force = cfg.capture.hold_force or TOKEN_LOAD
    load = disturbances(force, force * np.sqrt(geometry.polar_moment_per_mass(poly)))
    return geometry.centroid(poly), load, min(rb.max_force for rb in cfg.robots)


def set_capacity(cfg: FleetConfig, points: np.ndarray, normals: np.ndarray) -> float:
    """The share of ``capture.hold_force`` robots at ``points`` (object frame, outward
    ``normals``) resist in the worst direction with the weakest robot's force (≥ 1 holds)."""
    from controller.planning.hold import contact_wrenches, holding_capacity

    c, load, weakest = _hold_load(cfg)
    w = contact_wrenches(points, normals, c)
    return holding_capacity(w, np.full(len(points), weakest), load)


TOKEN_LOAD = 0.05  # N: the load a closure-only set (capture.hold_force 0) must hold
# m: an object vertex this close to a wall or an obstacle touches it (an object turned a degree
# or two in a corner keeps both walls; the hold allows 5 cm)
WALL_TOLERANCE = 0.04


def replan_pinned(
    cfg: FleetConfig,
    capture: CaptureSet,
    pose: np.ndarray,
    exclude: frozenset[int] = frozenset(),
    robots: int | None = None,
) -> CaptureSet | None:
    """The capture re-planned for an object pressed against walls or obstacles at ``pose``:
    capture points a robot disc cannot reach there are dropped, the walls count as fixed
    frictionless contacts, and points are added or moved until the set holds. ``exclude``:
    candidate nodes (indices) a robot could not get to; ``robots``: the robots available (None:
    the fleet). None: no set holds with them (the object is ``pinned`` out of reach)."""
    from controller.planning.hold import push_wrenches, wall_contacts

    poly = geometry.ensure_ccw(cfg.object_polygon())
    r = cfg.max_robot_radius
    bounds = cfg.bounds_array() if cfg.world.walls else None
    obstacles = cfg.obstacle_polygons()
    centres = geometry.transform(
        capture.candidates + (r + cfg.capture.clearance) * capture.candidate_normals, pose
    )
    # a robot can stand there only with the safety filter's margin to the wall or obstacle
    reach = r + cfg.approach.safety_margin
    allowed = ~geometry.discs_touch_static(centres, reach, obstacles, bounds, slack=0.0)
    allowed[list(exclude)] = False  # nodes robots were seen not to reach (a closed pocket)
    world = geometry.transform(poly, pose)
    pts, pushes = wall_contacts(world, obstacles, bounds, WALL_TOLERANCE)
    local = geometry.inverse_transform(pts, pose) if len(pts) else pts
    local_push = pushes @ geometry.rot(float(pose[2])) if len(pushes) else pushes
    fixed = push_wrenches(local, local_push, geometry.centroid(poly))
    chosen = np.array([i for i in capture.chosen if allowed[i]], int)
    res = reinforce_set(
        cfg, capture.candidates, capture.candidate_normals, chosen, allowed, fixed, robots
    )
    if not res.holds or len(res.chosen) == 0 or (robots is not None and len(res.chosen) > robots):
        return None
    return CaptureSet(
        capture.candidates[res.chosen],
        capture.candidate_normals[res.chosen],
        capture.objective,
        capture.form_closure,
        res.capacity if cfg.capture.hold_force > 0 else None,
        res.added,
        capture.candidates,
        capture.candidate_normals,
        res.chosen,
        walls=len(pts),
    )


def replan_for_robots(
    cfg: FleetConfig,
    capture: CaptureSet,
    keep: np.ndarray,
    robots: int,
    rng: np.random.Generator,
    pose: np.ndarray | None = None,
    exclude: frozenset[int] = frozenset(),
) -> CaptureSet | None:
    """The capture re-planned for the ``robots`` left after some were lost: the points of
    ``capture`` a robot still holds (``keep``, (M,) bool) stay and candidate nodes are added
    until the set holds again, with the first plan's certificates (first-order form closure,
    ``capture.hold_force`` held); when no such set exists, the GA once more, limited to
    ``robots``. A set that counts on walls (``capture.walls``) is re-planned against them at
    ``pose`` (``replan_pinned``). ``exclude``: nodes robots could not get to. None: no set
    closes the object with ``robots`` robots."""
    if robots < 1:
        return None
    keep = np.asarray(keep, bool)
    kept = dataclasses.replace(
        capture,
        points=capture.points[keep],
        normals=capture.normals[keep],
        chosen=capture.chosen[keep],
    )
    if capture.walls and pose is not None:
        return replan_pinned(cfg, kept, pose, exclude, robots)
    new = _repair(cfg, kept, robots, exclude) if len(kept.chosen) <= robots else None
    if new is not None:
        return new
    try:
        return plan_capture_set(cfg, rng, max_robots=robots)
    except CapturePlanError:
        return None


def _repair(
    cfg: FleetConfig, kept: CaptureSet, robots: int, exclude: frozenset[int]
) -> CaptureSet | None:
    """``kept``'s points reinforced to hold with at most ``robots`` points, in form closure
    (None: they cannot). Its objective stays the first GA set's."""
    from controller.planning.capture import certify_form_closure

    allowed = np.ones(len(kept.candidates), bool)
    allowed[list(exclude)] = False
    res = reinforce_set(
        cfg, kept.candidates, kept.candidate_normals, kept.chosen, allowed, robots=robots
    )
    if not res.holds or len(res.chosen) > robots:
        return None
    pts, nrm = kept.candidates[res.chosen], kept.candidate_normals[res.chosen]
    centroid = geometry.centroid(geometry.ensure_ccw(cfg.object_polygon()))
    if not certify_form_closure(pts, nrm, centroid):
        return None
    return CaptureSet(
        pts,
        nrm,
        kept.objective,
        True,
        res.capacity if cfg.capture.hold_force > 0 else None,
        kept.reinforced + res.added,
        kept.candidates,
        kept.candidate_normals,
        res.chosen,
    )
