"""The pushing arrangement for a route segment (Sharma §4, Eq. 5, confirmed by Vass's
contact-force LP): which candidate contacts the robots should hold to push the object along the
segment's twist. Pure: arrays and config in, an :class:`Arrangement` out, randomness through the
passed generator. The transport mission asks for it off the control tick (a job of kind
``rearrange``) and matches robots to the points it returns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.planning.contact_lp import GRAVITY, ContactForceLP, required_wrench
from controller.planning.transport import local_strategy
from controller.planning.transport_model import robust_wrenches

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


def errors_of(cfg: FleetConfig) -> tuple[float, float]:
    """The error model's (motion error m, the norm of ``transport.errors.position``; centre
    of mass error m per axis): the plans' margins (0, 0: condition 1, errors ignored)."""
    e = cfg.transport.errors
    return math.hypot(*e.position), float(e.com)


def error_note(cfg: FleetConfig) -> str:
    """What a too-heavy detail adds under the error model: the object it was planned for."""
    e = cfg.transport.errors
    if not (e.mass or e.friction):
        return ""
    return (
        f" (planned for the object {100 * e.mass:g} % heavier and its floor friction "
        f"{100 * e.friction:g} % higher, as transport.errors allows)"
    )


def planning_model(cfg: FleetConfig):
    """The object as the transport's planners see it (``transport_model.ObjectModel``): the
    config's, or under the error model (``transport.errors``, Yamashita's condition 2) the
    heaviest and roughest it may be, pushes near a vertex not counted."""
    from controller.planning.transport_model import ObjectModel

    o, e = cfg.object, cfg.transport.errors
    return ObjectModel.build(
        cfg.object_polygon(),
        o.mass * (1.0 + e.mass),
        o.floor_friction * (1.0 + e.friction),
        o.contact_friction,
        cfg.max_robot_radius,
        push_margin=errors_of(cfg)[0],
    )


def candidates(cfg: FleetConfig):
    """The candidate contact nodes of the arrangement (``capture.candidate_nodes``): the
    capture's, without those within the motion error of a vertex."""
    from controller.planning.capture import candidate_nodes

    poly = geometry.ensure_ccw(cfg.object_polygon())
    c = cfg.capture
    return candidate_nodes(poly, cfg.max_robot_radius, c.spacing, c.clearance, errors_of(cfg)[0])


def can_push(
    lp: ContactForceLP,
    model,
    twist: np.ndarray,
    pts: np.ndarray,
    inward: np.ndarray,
    fmax: np.ndarray,
    com_error: float = 0.0,
) -> bool:
    """Whether contacts (object-frame points, inward normals, force limits N) can move the
    object (``model``: ``transport_model.ObjectModel``) with ``twist`` (object frame, m/s and
    rad/s of the centroid), by the contact-force LP; wherever its centre of mass is within
    ±``com_error`` m of the centroid, with one."""
    if not np.any(twist):
        return True
    if len(pts) == 0:
        return False
    w = required_wrench(twist, model.mass, model.floor_friction, model.mean_radius)
    for wrench in robust_wrenches(w, com_error):
        res = lp.solve(
            pts - model.centroid, inward, fmax, np.ones(len(pts), bool), wrench,
            model.contact_friction, model.mean_radius,
        )  # fmt: skip
        if res.status != "optimal":
            return False
    return True


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
            fmax = np.full(len(pts), weakest)
            if can_push(lp, model, twist_v, pts, -nrm, fmax, errors_of(cfg)[1]):
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
    detail += error_note(cfg)
    return Arrangement(pts, nrm, value, n, "lp_capacity", feasible=False, detail=detail)


def pushing_set(
    cfg: FleetConfig, d: np.ndarray, n_push: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, float]:
    """Sharma Eq. 5 along D: the ``n_push`` candidate nodes pushing hardest along D (points,
    outward normals, value)."""
    from controller.planning.capture import CaptureParams, candidate_nodes, plan_push_arrangement

    r = cfg.max_robot_radius
    poly = geometry.ensure_ccw(cfg.object_polygon())
    err = errors_of(cfg)[0]
    params = CaptureParams.from_config(cfg.capture)
    if err > 0:  # the error model: off the vertices, robots twice the motion error further apart
        params = replace(params, edge_margin=err, clearance=params.clearance + 2.0 * err)
    idx, value = plan_push_arrangement(poly, r, d, n_push, params, rng)
    cand = candidate_nodes(poly, r, params.spacing, params.clearance, params.edge_margin)
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
    from controller.planning.capture_set import node_conflicts
    from controller.planning.hold import least_force_set, reinforce

    err, com = errors_of(cfg)
    cand = candidates(cfg)
    conflict = node_conflicts(cfg, cand.points, cand.normals, 2.0 * err)
    need = required_wrench(twist_v, model.mass, model.floor_friction, model.mean_radius)
    load = turn_margin * need
    # under the error model, every centre of mass it allows (the two torque extremes)
    loads = np.array([turn_margin * w for w in robust_wrenches(need, com)])
    start = least_force_set(cand.points, cand.normals, model.centroid, load, weakest, conflict)
    res = reinforce(
        cand.points,
        cand.normals,
        model.centroid,
        start[:robots],
        np.ones(len(cand.points), bool),
        conflict,
        weakest,
        -loads,
        robots,
    )
    return cand.points[res.chosen], cand.normals[res.chosen], res.capacity, len(res.chosen)
