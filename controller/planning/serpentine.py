"""Sharma et al. 2007 §4.3, the broken serpentine, as published: the whole strategy in one
module - its plan over the local planner's intervals (:func:`serpentine`, rolled out on the
transport model and scored with the same energy as the annealer's), its groups and switch rule,
and how a passive robot moves in the mission (:func:`passive_velocity`). The local planner's
registry (``controller.planning.transport.LOCAL_STRATEGIES``) says what else differs: no warm
start, passive followers, Eq. 5 alone for the arrangement.

- The pushing set is Eq. 5's alone, sized as in §4.1 (as many pushers as robots: no capture
  contact is kept beside it; ``planning.arrangement`` gives it).
- :func:`split_groups`: the pushers are split in two groups, one on each side of the line to
  the goal; a member must push *forward* (its push makes at least ``MIN_FORWARD`` of its unit
  force along D, i.e. within about 75° of the route): a contact that only grazes D joins no
  group. A straight pusher (no lateral component) joins the side its contact lies on (its
  torque), the smaller group first.
- One group is active (pushes), the other passive: it keeps its contact with *zero* force.
  :func:`passive_velocity` is how a passive robot moves: with the object's measured motion at
  its contact, held ``PASSIVE_GAP`` off the boundary (it follows; it never pushes).
- The groups switch when the CG deviates from the line by more than a threshold that shrinks
  toward the goal (:func:`serpentine_threshold`).

Pure: arrays and the rollout in, a trace out; no I/O, no clock.
"""

from __future__ import annotations

import math

import numpy as np

from controller import geometry
from controller.planning.contact_lp import twist_for_wrench
from controller.planning.transport_model import Rollout, Trace
from controller.planning.transport_types import (
    FOLLOW,
    IDLE,
    PUSH,
    FloatArray,
    IntArray,
    TransportParams,
)

#: a group member's push has at least this share of its unit force along the route (cos 75°)
MIN_FORWARD = 0.26
#: lateral share below which a push counts as straight along the route
STRAIGHT = 1e-3
#: m a passive robot keeps between its disc and the boundary (contact without force)
PASSIVE_GAP = 0.004


def split_groups(push: FloatArray, offset: FloatArray, direction: FloatArray) -> IntArray:
    """Per contact: 0 (pushes toward the left of the route), 1 (toward the right) or −1 (no
    contact or not forward enough: never pushes).

    push (k, 2): unit push directions (world; NaN rows: no contact); offset (k, 2): contact
    point minus the object's centroid (world, m); direction (2,): the route's unit tangent."""
    d = np.asarray(direction, float)
    left = np.array([-d[1], d[0]])
    k = len(push)
    groups = np.full(k, -1, np.int64)
    straight = []
    for i in range(k):
        p = push[i]
        if not np.all(np.isfinite(p)) or float(p @ d) < MIN_FORWARD:
            continue
        lat = float(p @ left)
        if lat > STRAIGHT:
            groups[i] = 0
        elif lat < -STRAIGHT:
            groups[i] = 1
        else:
            straight.append(i)
    for i in straight:  # a push behind the left half turns the object right: left group
        side = float(offset[i] @ left)
        n0, n1 = int(np.sum(groups == 0)), int(np.sum(groups == 1))
        if n0 != n1:
            groups[i] = 0 if n0 < n1 else 1
        else:
            groups[i] = 1 if side > 0 else 0
    return groups


def passive_velocity(
    contact_centre: FloatArray,
    position: FloatArray,
    inward: FloatArray,
    object_pose: FloatArray,
    object_velocity: FloatArray | None,
    gain: float,
    vmax: float,
    gap: float = PASSIVE_GAP,
) -> FloatArray:
    """World velocity (2,) of a passive robot: the measured object velocity at its contact
    centre (feed-forward: it moves *with* the object, not with the plan) plus ``gain`` (1/s)
    times the error to that centre moved ``gap`` (m) away from the object along −``inward``.

    contact_centre (2,): where the disc's centre touches the boundary at the object's current
    pose; position (2,): the robot's centre; inward (2,) unit push direction (world);
    object_pose (3,) and object_velocity (3,): (x, y, θ) and (vx, vy, ωz) of the object frame
    (None: unknown, no feed-forward). Clipped to ``vmax`` m/s."""
    target = np.asarray(contact_centre, float) - gap * np.asarray(inward, float)
    v = gain * (target - np.asarray(position, float))
    if object_velocity is not None:
        w = np.asarray(object_velocity, float)
        rel = np.asarray(contact_centre, float) - np.asarray(object_pose, float)[:2]
        v = v + w[:2] + w[2] * np.array([-rel[1], rel[0]])
    speed = float(np.hypot(v[0], v[1]))
    return v if speed <= vmax else v * (vmax / speed)


def serpentine_groups(roll: Rollout) -> IntArray:
    """Per robot: 0 (pushes toward the left of the route), 1 (toward the right), −1 (no
    contact, or its push is not forward enough: it never pushes, it stays passive);
    :func:`split_groups` at the start pose."""
    st, m = roll.start, roll.model
    d = roll.route.tangent(roll._q(st.pose))
    rot = geometry.rot(st.pose[2])
    push = np.full((roll.k, 2), np.nan)
    offset = np.zeros((roll.k, 2))
    for i, node in enumerate(st.nodes):
        if node >= 0:
            push[i] = rot @ (-m.normals[node])
            offset[i] = rot @ (m.nodes[node] - m.centroid)
    return split_groups(push, offset, d)


def serpentine_threshold(roll: Rollout, s: float, params: TransportParams) -> float:
    """Switch distance (m): shrinks with the route left to the goal."""
    remaining = max(roll.route.length - s, 0.0)
    frac = remaining / roll.route.length if roll.route.length > 0 else 0.0
    h = params.serpentine_deviation * min(1.0, frac)
    return max(params.serpentine_min_deviation, h)


def serpentine_switch(group: int | None, signed_dev: float, h: float, groups: IntArray) -> int:
    """The active group after the deviation rule (signed_dev > 0: left of the route)."""
    if group is None:
        group = 1 if signed_dev > 0 else 0
    elif group == 0 and signed_dev > h:
        group = 1
    elif group == 1 and signed_dev < -h:
        group = 0
    if not np.any(groups == group) and np.any(groups == 1 - group):
        group = 1 - group  # one side has no pushers: the other pushes alone
    return group


def _group_twist(roll: Rollout, sim, members: IntArray) -> FloatArray:
    """World twist direction the group's wrench (all at max_force) drives, at ``speed`` in
    pose-arc metres per second, never past the subgoal."""
    m, p = roll.model, roll.params
    if len(members) == 0:
        return np.zeros(3)
    nodes = np.array([sim.nodes[i] for i in members])
    rel = m.nodes[nodes] - m.centroid
    push = -m.normals[nodes]
    f = roll.fmax[members]
    wrench = np.array(
        [
            f @ push[:, 0],
            f @ push[:, 1],
            f @ (rel[:, 0] * push[:, 1] - rel[:, 1] * push[:, 0]),
        ]
    )
    t, _ = twist_for_wrench(wrench, m.mass, m.floor_friction, m.mean_radius)
    v = geometry.rot(sim.pose[2]) @ t[:2]
    w = np.array([v[0], v[1], t[2]])
    norm = math.sqrt(v[0] ** 2 + v[1] ** 2 + (m.mean_radius * t[2]) ** 2)
    if norm < 1e-12:
        return np.zeros(3)
    left = max(roll.route.s_subgoal - sim.s, 0.0)
    return w / norm * min(p.speed, left / roll.dt)


def serpentine(roll: Rollout, group: int | None) -> tuple[Trace, int | None]:
    """Sharma's broken serpentine over the plan's intervals; returns the trace and the group
    pushing in the first interval."""
    p = roll.params
    groups = serpentine_groups(roll)
    sim = roll.start
    rows, sims, eff, terms, tws, lps = [], [sim], [], [], [], []
    first = None
    for _ in range(p.intervals):
        _, dev, side = roll.route.locate(roll._q(sim.pose))
        group = serpentine_switch(group, dev * side, serpentine_threshold(roll, sim.s, p), groups)
        first = group if first is None else first
        row = np.array(
            [
                PUSH if groups[i] == group else (FOLLOW if sim.nodes[i] >= 0 else IDLE)
                for i in range(roll.k)
            ],
            np.int64,
        )
        members = np.flatnonzero((groups == group) & (np.array(sim.nodes) >= 0))
        sim, e, t, w, lp = roll.step(sim, row, _group_twist(roll, sim, members))
        for lst, v in ((rows, row), (sims, sim), (eff, e), (terms, t), (tws, w), (lps, lp)):
            lst.append(v)
    matrix = np.array(rows, np.int64).reshape(p.intervals, roll.k)
    trace = Trace(matrix, tuple(sims), tuple(eff), tuple(terms), tuple(tws), tuple(lps))
    return trace, (first if np.any(groups >= 0) else None)
