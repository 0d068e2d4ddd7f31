"""The pushing arrangement for a route segment (Sharma §4, Eq. 5, confirmed by Vass's
contact-force LP): which candidate contacts the robots should hold to push the object along the
segment's twist. Pure: arrays and config in, an :class:`Arrangement` out, randomness through the
passed generator. The transport mission asks for it off the control tick (a job of kind
``rearrange``) and matches robots to the points it returns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.planning.contact_lp import GRAVITY, ContactForceLP, required_wrench
from controller.planning.transport import local_strategy

TURN_SHARE = 0.3  # a segment whose turn takes more than this share of the unit twist turns
TURN_MARGIN = 1.2  # a set chosen by the LP produces this times the wrench the segment needs


@dataclass(frozen=True)
class Arrangement:
    """Contact points and outward normals (K, 2), object frame; ``value``: Eq. 5's value, or
    the capacity of an LP set (≥ 1: it can move the object as asked); ``pushers``: K;
    ``basis``: ``eq5`` or ``lp_capacity``; ``feasible``: the set can move the object at all
    (False: no set of contacts found, every robot at its limit, overcomes the floor friction
    along the segment: ``detail`` says the force needed against the force available)."""

    points: np.ndarray
    normals: np.ndarray
    value: float
    pushers: int
    basis: str
    feasible: bool = True
    detail: str = ""


def can_push(
    lp: ContactForceLP,
    model,
    twist: np.ndarray,
    pts: np.ndarray,
    inward: np.ndarray,
    fmax: np.ndarray,
) -> bool:
    """Whether contacts (object-frame points, inward normals, force limits N) can move the
    object (``model``: ``transport_model.ObjectModel``) with ``twist`` (object frame, m/s and
    rad/s of the centroid), by the contact-force LP."""
    if not np.any(twist):
        return True
    if len(pts) == 0:
        return False
    w = required_wrench(twist, model.mass, model.floor_friction, model.mean_radius)
    res = lp.solve(
        pts - model.centroid, inward, fmax, np.ones(len(pts), bool), w,
        model.contact_friction, model.mean_radius,
    )  # fmt: skip
    return res.status == "optimal"


def plan_arrangement(
    cfg: FleetConfig,
    model,
    twist: np.ndarray,
    speed: float,
    weakest: float,
    robots: int,
    turn_margin: float,
    rng: np.random.Generator,
    strategy: str = "sa",
) -> Arrangement:
    """The contact set for a segment whose unit twist is ``twist`` (object frame), pushed at
    ``speed`` m/s by ``robots`` robots whose weakest pushes ``weakest`` N: Sharma's Eq. 5 along
    the travel direction with the fewest pushers that overcome the floor friction (plus one for
    the torque), then one more at a time up to every robot, each confirmed by the
    contact-force LP at the weakest robot's limit; a segment that mostly turns the object, or
    one no Eq. 5 set can push, gets the least-force set of the LP over all candidate nodes
    (:func:`wrench_set`). When that set cannot produce the wrench either, the arrangement is
    not ``feasible`` (the transport fails ``too_heavy`` before anyone pushes), with a
    ``detail`` naming the force needed, the share the best set reaches and the fleet's summed
    force; a turning segment is given the benefit of the doubt while the fleet's summed force
    covers the need. ``strategy`` ``serpentine`` (Sharma §4.1 as published): Eq. 5 for every
    robot, nothing else."""
    d = twist[:2] if np.any(twist[:2]) else np.array([1.0, 0.0])
    if local_strategy(strategy).eq5_alone:  # serpentine, Sharma §4.1: Eq. 5 for every robot
        pts, nrm, value = pushing_set(cfg, d, robots, rng)
        return Arrangement(pts, nrm, value, robots, "eq5")
    lp = ContactForceLP(max(robots, 1), friction=model.contact_friction > 0)
    twist_v = twist * speed
    turning = abs(twist[2]) * model.mean_radius > TURN_SHARE
    if not turning:
        friction = model.floor_friction * model.mass * GRAVITY
        first = int(min(robots, math.ceil(friction / weakest) + 1))
        # more pushers while the LP says the set cannot push, up to every robot
        for n in range(first, robots + 1):
            pts, nrm, value = pushing_set(cfg, d, n, rng)
            if can_push(lp, model, twist_v, pts, -nrm, np.full(len(pts), weakest)):
                return Arrangement(pts, nrm, value, n, "eq5")
    pts, nrm, value, n = wrench_set(cfg, model, twist_v, weakest, robots, turn_margin)
    need = float(np.hypot(*required_wrench(twist_v, model.mass, model.floor_friction, 1.0)[:2]))
    fleet = robots * weakest
    if value * turn_margin >= 1.0 - 1e-9 or (turning and need <= fleet):
        # it pushes (the LP: the set produces the wrench needed, every contact within the
        # weakest robot's force), or a turn short of it with the fleet's summed force to spare
        # (the LP's turning load is a rough model: turn-180-pybullet turns with such a set)
        return Arrangement(pts, nrm, value, n, "lp_capacity")
    # no set found can push the object along this segment: the LP knows it before anyone
    # pushes (before, a push set short of the floor friction stalled after nine re-arrangements)
    detail = (
        f"too heavy to push: the floor friction needs {need:.1f} N; the best set of contacts "
        f"({n} robots where they fit, {weakest:g} N each) reaches {100 * value * turn_margin:.0f}"
        f" % of it; the {robots} robots have {fleet:.1f} N in all"
    )
    if need <= fleet:
        detail += " but cannot all push on the faces that move it this way"
    return Arrangement(pts, nrm, value, n, "lp_capacity", feasible=False, detail=detail)


def pushing_set(
    cfg: FleetConfig, d: np.ndarray, n_push: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, float]:
    """Sharma Eq. 5 along D: the ``n_push`` candidate nodes pushing hardest along D (points,
    outward normals, value)."""
    from controller.planning.capture import CaptureParams, candidate_nodes, plan_push_arrangement

    r = cfg.max_robot_radius
    poly = geometry.ensure_ccw(cfg.object_polygon())
    params = CaptureParams.from_config(cfg.capture)
    idx, value = plan_push_arrangement(poly, r, d, n_push, params, rng)
    cand = candidate_nodes(poly, r, cfg.capture.spacing, cfg.capture.clearance)
    return cand.points[idx], cand.normals[idx], float(value)


def wrench_set(
    cfg: FleetConfig,
    model,
    twist_v: np.ndarray,
    weakest: float,
    robots: int,
    turn_margin: float,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The support of the least-force LP for the wrench ``twist_v`` needs (times
    ``turn_margin``) over every candidate node, reinforced (``planning.hold``) until it can
    produce that wrench within ``weakest`` N per contact with at most ``robots`` contacts;
    the value is that capacity."""
    from controller.planning.capture import candidate_nodes
    from controller.planning.hold import least_force_set, reinforce

    r = cfg.max_robot_radius
    poly = geometry.ensure_ccw(cfg.object_polygon())
    cand = candidate_nodes(poly, r, cfg.capture.spacing, cfg.capture.clearance)
    centres = cand.points + r * cand.normals
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = gap < 2 * r + max(cfg.capture.clearance, cfg.approach.safety_margin)
    np.fill_diagonal(conflict, False)
    need = required_wrench(twist_v, model.mass, model.floor_friction, model.mean_radius)
    load = turn_margin * need
    start = least_force_set(cand.points, cand.normals, model.centroid, load, weakest, conflict)
    res = reinforce(
        cand.points,
        cand.normals,
        model.centroid,
        start[:robots],
        np.ones(len(cand.points), bool),
        conflict,
        weakest,
        -load[None],
        robots,
    )
    return cand.points[res.chosen], cand.normals[res.chosen], res.capacity, len(res.chosen)
