"""The CBF safety filter: head-on robots keep the margin; obstacles, bounds, stale robots."""

from __future__ import annotations

import numpy as np

from controller.planning.safety import SafetyFilter

BOUNDS = np.array([[0.0, 0.0], [10.0, 10.0]])


def simulate(flt, p, goal_vel, steps=200, dt=0.05, polys=(), stale=None):
    dmin = np.inf
    for _ in range(steps):
        res = flt.filter(p, goal_vel(p), list(polys), stale=stale)
        p = p + dt * res.velocities
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        d[np.eye(len(p), dtype=bool)] = np.inf
        dmin = min(dmin, float(d.min()))
    return p, dmin


def test_head_on_keeps_margin():
    r = np.array([0.1, 0.1])
    flt = SafetyFilter(r, np.array([0.5, 0.5]), BOUNDS, 0, margin=0.05)
    p = np.array([[3.0, 5.0], [7.0, 5.0]])
    _, dmin = simulate(flt, p, lambda p: np.array([[0.5, 0.0], [-0.5, 0.0]]))
    assert dmin >= 0.2 + 0.05 - 1e-3


def test_many_robots_swap_keep_margin():
    n = 12
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    p = 5 + 3 * np.stack([np.cos(ang), np.sin(ang)], 1)
    goal = 5 - 3 * np.stack([np.cos(ang), np.sin(ang)], 1)
    flt = SafetyFilter(np.full(n, 0.1), np.full(n, 0.4), BOUNDS, 0, margin=0.05)

    def vel(p):
        v = goal - p
        s = np.linalg.norm(v, axis=1, keepdims=True)
        return v / np.maximum(s, 1e-9) * np.minimum(s, 0.4)

    _, dmin = simulate(flt, p, vel, steps=300)
    assert dmin >= 0.25 - 2e-3


def test_obstacle_and_bounds():
    box = np.array([[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]])
    flt = SafetyFilter(np.array([0.1]), np.array([0.5]), BOUNDS, 1, margin=0.05)
    p = np.array([[2.0, 5.0]])
    p2, _ = simulate(flt, p, lambda p: np.array([[0.5, 0.0]]), polys=[box])
    assert p2[0, 0] <= 4.0 - 0.1 - 0.05 + 1e-3
    p3, _ = simulate(flt, np.array([[9.0, 9.0]]), lambda p: np.array([[0.5, 0.5]]), polys=[box])
    assert np.all(p3 <= 10.0 - 0.15 + 1e-3)


def test_stale_robot_stays_and_is_avoided():
    r = np.array([0.1, 0.1])
    flt = SafetyFilter(r, np.array([0.5, 0.5]), BOUNDS, 0, margin=0.05)
    stale = np.array([False, True])
    p = np.array([[3.0, 5.0], [5.0, 5.0]])
    p2, dmin = simulate(flt, p, lambda p: np.array([[0.5, 0.0], [0.3, 0.0]]), stale=stale)
    assert np.allclose(p2[1], [5.0, 5.0])
    assert dmin >= 0.25 - 1e-3


def test_warm_equals_cold():
    rng = np.random.default_rng(0)
    n = 8
    p = rng.uniform(1, 9, (n, 2))
    u = rng.uniform(-0.4, 0.4, (n, 2))
    a = SafetyFilter(np.full(n, 0.1), np.full(n, 0.5), BOUNDS, 0)
    b = SafetyFilter(np.full(n, 0.1), np.full(n, 0.5), BOUNDS, 0, warm=False)
    for _ in range(3):
        ra, rb = a.filter(p, u, []), b.filter(p, u, [])
        assert np.allclose(ra.velocities, rb.velocities, atol=2e-3)
        p = p + 0.05 * ra.velocities


def test_infeasible_stops_the_robots_concerned():
    # two robots already deep inside each other's margin: no bounded velocity restores it now,
    # and robot-robot rows are never relaxed: both stop, the third goes on
    r = np.full(3, 0.1)
    flt = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05)
    p = np.array([[5.0, 5.0], [5.05, 5.0], [8.0, 8.0]])
    res = flt.filter(p, np.array([[0.3, 0.0], [-0.3, 0.0], [0.2, 0.1]]), [])
    assert not res.status.startswith("solved")
    assert res.stopped.tolist() == [True, True, False]
    assert np.allclose(res.velocities[:2], 0.0)
    assert np.allclose(res.velocities[2], [0.2, 0.1])


def test_a_robot_squeezed_between_the_object_and_a_wall_slides_out():
    # the object pushes a robot against the west wall: recovering both margins at once is
    # impossible (infeasible before the relaxation); it may not go closer to either, and keeps
    # its motion along the wall
    r = np.full(1, 0.1)
    flt = SafetyFilter(r, np.full(1, 0.4), BOUNDS, 1, margin=0.05)
    wall_gap = BOUNDS[0][0] + 0.12  # inside the wall margin (0.15)
    box = np.array([[wall_gap + 0.12, 4.0], [wall_gap + 1.0, 4.0], [wall_gap + 1.0, 6.0],
                    [wall_gap + 0.12, 6.0]])  # fmt: skip
    p = np.array([[wall_gap, 5.0]])
    res = flt.filter(p, np.array([[0.0, 0.3]]), [box], motion=[(-0.2, 0.0, 0.0)])
    assert res.status == "relaxed" and not res.stopped.any()
    assert res.velocities[0, 1] > 0.2  # it slides along the wall instead of freezing
    assert res.velocities[0, 0] >= -1e-4  # and comes no closer to the wall
    # without the relaxation (transport) the same robot stops
    stop = SafetyFilter(r, np.full(1, 0.4), BOUNDS, 1, margin=0.05)
    res = stop.filter(p, np.array([[0.0, 0.3]]), [box], motion=[(-0.2, 0.0, 0.0)], relax=False)
    assert res.stopped.all() and np.allclose(res.velocities, 0.0)
