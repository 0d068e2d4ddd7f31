"""Sharma et al. 2007 §4.3, the broken serpentine, as published: pure pieces the transport
planner (:func:`controller.planning.transport.serpentine`) and the mission's execution use.

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
  toward the goal (:func:`controller.planning.transport.serpentine_threshold`).

All inputs are arrays in one frame; no I/O, no clock.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

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
