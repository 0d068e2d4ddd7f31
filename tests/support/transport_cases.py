"""Seeded transport situations shared by the transport tests and bench/transport.py."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.planning.contact_lp import required_wrench
from controller.planning.transport_model import ObjectModel
from controller.planning.transport_types import RobotState, RouteSegment, TransportState

L_SHAPE = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], dtype=float)
BOX = np.array([[-0.3, -0.2], [0.3, -0.2], [0.3, 0.2], [-0.3, 0.2]], dtype=float)


def straight_route(start, goal, step: float = 0.1) -> np.ndarray:
    """Waypoints (k, 3) from start to goal pose: a straight line, heading blended linearly."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    n = max(2, int(np.ceil(np.linalg.norm(goal[:2] - start[:2]) / step)) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    dth = float(geometry.wrap_angle(goal[2] - start[2]))
    xy = start[:2] + t * (goal[:2] - start[:2])
    return np.column_stack([xy, start[2] + t[:, 0] * dth])


def robots_at(
    model: ObjectModel, pose, nodes, radius=0.1, max_force=6.0, max_speed=0.4, actions=None
) -> tuple[RobotState, ...]:
    """Robots touching the given boundary nodes of the object at ``pose``."""
    out = []
    for k, node in enumerate(nodes):
        centre = model.centre(int(node), radius)
        world = geometry.transform(centre[None], pose)[0]
        fmax = max_force[k] if np.ndim(max_force) else max_force
        out.append(
            RobotState(
                position=world,
                radius=radius,
                max_force=float(fmax),
                max_speed=max_speed,
                contact=(model.nodes[node].copy(), -model.normals[node].copy()),
                action=None if actions is None else actions[k],
                id=f"r{k + 1}",
            )
        )
    return tuple(out)


def node_near(model: ObjectModel, point) -> int:
    return int(np.argmin(np.linalg.norm(model.nodes - np.asarray(point, float), axis=1)))


def push_case(
    n_robots: int = 6,
    mass: float = 4.0,
    mu: float = 0.2,
    max_force=6.0,
    goal=(6.0, 3.0, 0.0),
    obj=L_SHAPE,
    seed: int | None = None,
) -> TransportState:
    """An L-shaped crate at (3, 3, 0) to be carried along +x: robots on the back edge (x = 0)
    and spread over the other edges (seeded shuffle of the others when ``seed`` is given)."""
    model = ObjectModel.build(obj, mass, mu, 0.0, 0.1)
    pose = np.array([3.0, 3.0, 0.0])
    fit = np.flatnonzero(model.fit)
    back = [node_near(model, (0.0, 0.25)), node_near(model, (0.0, 0.75))]
    rest = fit[(np.arange(len(fit)) % 17) == 0]
    if seed is not None:
        rest = np.random.default_rng(seed).permutation(rest)
    nodes = list(back)
    for nd in rest:
        if len(nodes) >= n_robots:
            break
        c = model.centre(int(nd), 0.1)
        if all(np.linalg.norm(c - model.centre(q, 0.1)) > 0.25 for q in nodes):
            nodes.append(int(nd))
    robots = robots_at(model, pose, nodes, max_force=max_force)
    route = RouteSegment(straight_route(pose, goal))
    return TransportState(model, pose, robots, route)


def random_lp(rng: np.random.Generator, n: int, contact_friction: float = 0.0):
    """A random contact-force LP: n contacts on a random box, random twist, mass, friction and
    force limits spread so that feasible and infeasible instances both occur. Returns the
    arguments of ContactForceLP.solve as a dict."""
    w, h = rng.uniform(0.3, 1.5, 2)
    poly = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    e = rng.integers(0, 4, n)
    s = rng.uniform(0.05, 0.95, n)
    pts = poly[e] + s[:, None] * (poly[(e + 1) % 4] - poly[e])
    nrm = -geometry.outward_normals(poly)[e]
    mass, mu = rng.uniform(1, 8), rng.uniform(0.1, 0.5)
    fmax = rng.uniform(0.3, 1.2, n) * mu * mass * 9.81 * rng.uniform(0.5, 2.0)
    active = rng.random(n) < 0.85
    rbar = 0.25 * (w + h)
    if rng.random() < 0.5 and active.any():
        # a wrench the active contacts can make in direction; the forces may not suffice
        lam = rng.exponential(size=n) * active
        f = lam[:, None] * nrm
        wrench = np.array(
            [f[:, 0].sum(), f[:, 1].sum(), np.sum(pts[:, 0] * f[:, 1] - pts[:, 1] * f[:, 0])]
        )
        wrench *= mu * mass * 9.81 / max(np.linalg.norm(wrench[:2]), 1e-9)
    else:
        twist = rng.normal(size=3)
        twist[2] *= rng.uniform(0, 2)
        wrench = required_wrench(twist, mass, mu, rbar)
    return dict(
        points=pts,
        normals=nrm,
        max_force=fmax,
        active=active,
        wrench=wrench,
        contact_friction=contact_friction,
        length=rbar,
    )


DIAMOND = np.array([[0.0, -0.35], [0.35, 0.0], [0.0, 0.35], [-0.35, 0.0]], dtype=float)


def diamond_case(max_force: float = 10.0, mass: float = 2.0, length: float = 3.0) -> TransportState:
    """A square turned 45° (a diamond) to be carried along +x by two robots on its two rear
    faces: each pushes through the centroid, one toward the left of the route, one toward the
    right (Sharma's two serpentine groups)."""
    model = ObjectModel.build(DIAMOND, mass, 0.2, 0.0, 0.1)
    pose = np.array([2.0, 3.0, 0.0])
    nodes = [node_near(model, (-0.175, -0.175)), node_near(model, (-0.175, 0.175))]
    robots = robots_at(model, pose, nodes, max_force=max_force)
    route = RouteSegment(straight_route(pose, (2.0 + length, 3.0, 0.0)))
    return TransportState(model, pose, robots, route)
