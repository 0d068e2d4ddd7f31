"""Braces for a fast object (issue 34, item 10): while the fleet approaches an object moving
at ``approach.brace_speed`` or faster, robots ahead of it wait in its path at contact points
that can hold it back and, touching, stand still (commanded exactly zero, their barrier holding
its ground). The points are the least-force set of frictionless contacts that resists a push
along the object's motion with no turn (``planning.hold.least_force_set``): on a face square to
the motion one robot, on a face at a slant two (one on the face, one on the side it would slide
toward). The object's drive cannot push robots that hold their ground, so it stops, and the
rest of the fleet, which could not catch it from behind, closes in on an object at rest. The
braces meet it together, and stay braces for the rest of the approach (the object they stopped
is slow: letting go would free it); the job hands the capture points to no other robots while
they brace.

Pure: arrays in, arrays out.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.planning.capture import candidate_nodes
from controller.planning.hold import least_force_set

#: at most this many braces: the rest of the fleet approaches as before
MAX_BRACES = 3


def brace_points(
    polygon: np.ndarray, radius: float, margin: float, direction: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Object-frame contact points and outward normals (K, 2), K ≤ ``MAX_BRACES``, that
    together resist a push of the object (its ``polygon``, CCW, object frame) along
    ``direction`` (object frame) with no turn: the least-force set of candidate nodes a robot
    disc of ``radius`` fits at, a diameter and ``margin`` apart (the safety filter's)."""
    poly = geometry.ensure_ccw(np.asarray(polygon, float))
    apart = 2.0 * radius + margin
    cand = candidate_nodes(poly, radius, apart, 1e-3)
    centres = cand.points + radius * cand.normals
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = gap < apart - 1e-9
    np.fill_diagonal(conflict, False)
    d = np.asarray(direction, float) / max(float(np.linalg.norm(direction)), 1e-12)
    load = np.array([-d[0], -d[1], 0.0])  # the contacts push back against the drive
    pick = least_force_set(
        cand.points, cand.normals, geometry.centroid(poly), load, 10.0, conflict
    )[:MAX_BRACES]
    return cand.points[pick], cand.normals[pick]


def choose_braces(
    robots: np.ndarray, centre: np.ndarray, velocity: np.ndarray, targets: np.ndarray
) -> np.ndarray:
    """(M,) index of the brace target each assigned robot (``robots`` (M, 2)) takes, −1 for
    none: robots ahead of the object (past its ``centre`` along ``velocity``) to the world
    ``targets`` (K, 2), the nearest overall (an assignment)."""
    out = np.full(len(robots), -1)
    d = np.asarray(velocity[:2], float) / max(float(np.hypot(*velocity[:2])), 1e-12)
    ahead = np.flatnonzero((np.asarray(robots, float) - np.asarray(centre, float)) @ d > 0)
    if len(ahead) == 0 or len(targets) == 0:
        return out
    cost = np.linalg.norm(robots[ahead][:, None] - np.asarray(targets)[None], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    out[ahead[rows]] = cols
    return out


def brace_masks(
    n: int, assignment: np.ndarray, brace: np.ndarray, gap: np.ndarray, tolerance: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(N,) robots bracing (allowed to touch the object, holding their ground) and (N,) those
    of them touching it (within ``tolerance`` m of its surface: commanded exactly zero), or
    None where there are none."""
    touch = np.zeros(n, bool)
    touch[assignment[brace]] = True
    still = np.zeros(n, bool)
    still[assignment[brace & (gap < tolerance)]] = True
    return (touch if touch.any() else None), (still if still.any() else None)


def plan_braces(
    polygon: np.ndarray,
    radius: float,
    margin: float,
    gap: float,
    pose: np.ndarray,
    robots: np.ndarray,
    velocity: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The braces for an object (``polygon`` object frame, at ``pose``) moving with world
    ``velocity``: (M,) which of the assigned robots (``robots`` (M, 2)) brace, and (M, 4) the
    object-frame contact point and outward normal each takes instead of its capture point (NaN
    for the others); ``margin``: m between braces beyond their discs; ``gap``: m off the
    surface they are matched to the robots at."""
    th = float(pose[2])
    local = geometry.rot(th).T @ np.asarray(velocity[:2], float)
    pts, nrm = brace_points(polygon, radius, margin, local)
    centres = pts + (radius + gap) * nrm
    world = geometry.transform(centres, pose)
    mid = geometry.transform(geometry.centroid(geometry.ensure_ccw(polygon))[None], pose)[0]
    k = choose_braces(robots, mid, velocity, world)
    at = np.full((len(robots), 4), np.nan)
    at[k >= 0] = np.hstack([pts, nrm])[k[k >= 0]]
    return k >= 0, at
