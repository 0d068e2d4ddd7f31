"""Hand-made capture sets for the approach tests (the GA capture planner is another issue)."""

from __future__ import annotations

import numpy as np


def rectangle_points(w: float, h: float, x0: float = 0.0, y0: float = 0.0):
    """Four form-closure points on a w x h rectangle at (x0, y0): each side's point is off its
    midpoint (a pinwheel), so the contact normals have moment about the centre."""
    pts = np.array(
        [
            [x0 + 0.7 * w, y0],
            [x0 + w, y0 + 0.7 * h],
            [x0 + 0.3 * w, y0 + h],
            [x0, y0 + 0.3 * h],
        ]
    )
    nrm = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    return pts, nrm


def l_shape_points():
    """Four points on the shipped L crate (1 m, arms 0.4 m): bottom, right end, inner top, left."""
    pts = np.array([[0.7, 0.0], [1.0, 0.25], [0.25, 1.0], [0.0, 0.3]])
    nrm = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    return pts, nrm


def nearest_assignment(points_world: np.ndarray, robots_xy: np.ndarray) -> np.ndarray:
    """Greedy nearest robot per point (distinct robots)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.linalg.norm(points_world[:, None] - robots_xy[None], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    out = np.zeros(len(points_world), int)
    out[rows] = cols
    return out
