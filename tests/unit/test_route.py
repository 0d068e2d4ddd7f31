"""The object route (Yamashita et al. §3): exact C-space, swept moves, heuristics, weighted A*.

Every route a test gets is checked move by move with shapely, independently of the planner's
own geometry (:func:`assert_route_clear`): a straight move's swept footprint is built exactly
(the polygon at both ends and each edge swept), a turn is sampled finely with its sampling
error bounded.
"""

from __future__ import annotations

import dataclasses
import heapq
import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controller import geometry
from controller.config import RouteSection
from controller.planning import heuristics
from controller.planning.cspace import (
    MOVES_8,
    FootprintChecker,
    GridFrame,
    RobotCSpace,
    arc_segment_distance,
    build_object_cspace,
    build_robot_cspace,
    segment_distance,
)
from controller.planning.roadmap import ROBOT_HEURISTICS, RobotRoadmap, plan_robot_route
from controller.planning.route import RoutePlanner, plan_route
from tests.support.route_check import (
    assert_route_clear,
    clearance,
    placed,
    step_clearance,
)

L_SHAPE = np.array(
    [[-0.2, -0.15], [0.2, -0.15], [0.2, 0.0], [-0.05, 0.0], [-0.05, 0.15], [-0.2, 0.15]]
)
CRATE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]])
BOUNDS = np.array([[0.0, 0.0], [4.0, 4.0]])
PARAMS = RouteSection(resolution=0.1, heading_bins=12, heuristic="cost_to_go")
RADIUS = 0.05


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def wall_map() -> list[np.ndarray]:
    """A wall across the middle with one gap: the object must go round."""
    return [rect(1.9, 0.0, 2.1, 2.4), rect(0.0, 3.4, 0.6, 4.0)]


# --------------------------------------------------------------------------- exact geometry


def test_segment_and_arc_distances_match_shapely():
    rng = np.random.default_rng(1)
    for _ in range(300):
        a = rng.uniform(-1, 1, (4, 2))
        want = shapely.LineString(a[:2]).distance(shapely.LineString(a[2:]))
        assert segment_distance(a[0], a[1], a[2], a[3]) == pytest.approx(want, abs=1e-12)
    for _ in range(300):
        c = rng.uniform(-1, 1, 2)
        r, a0, sw = rng.uniform(0.05, 1.5), rng.uniform(-4, 4), rng.uniform(-6.28, 6.28)
        q = rng.uniform(-2, 2, (2, 2))
        t = np.linspace(0, 1, 4001)
        arc = c + r * np.stack([np.cos(a0 + t * sw), np.sin(a0 + t * sw)], 1)
        sampled = shapely.LineString(arc).distance(shapely.LineString(q))
        got = float(arc_segment_distance(c, r, a0, sw, q[0], q[1]))
        # the sampled polyline is off the arc by at most its sag r (1 - cos(dt / 2))
        assert abs(got - sampled) <= r * (1 - math.cos(abs(sw) / 8000)) + 1e-12


def test_swept_moves_are_decided_exactly():
    obs = [rect(2.2, 2.2, 2.5, 2.4), np.array([[0.4, 2.4], [0.6, 2.7], [0.3, 2.8]])]
    obs.append(rect(1.5, 0.8, 1.53, 2.0))  # thin: a move across it has free ends
    bounds = np.array([[0.0, 0.0], [3.0, 3.0]])
    chk = FootprintChecker(bounds, obs, L_SHAPE, 0.1)
    rng = np.random.default_rng(2)
    seen = {True: 0, False: 0}
    for i in range(300):
        if i % 2:  # from the left of the thin wall to its right, across or round its ends
            p = np.r_[rng.uniform(0.6, 1.1), rng.uniform(0.6, 2.2), rng.uniform(-3, 3)]
            q = np.r_[rng.uniform(1.9, 2.4), p[1] + rng.uniform(-0.6, 0.6), p[2]]
        else:  # turns next to the obstacles
            p = np.r_[rng.uniform(0.5, 2.8, 2), rng.uniform(-3, 3)]
            q = p + np.r_[0.0, 0.0, rng.uniform(-1.2, 1.2)]
        if not chk.poses_free(np.array([p, q])).all():
            continue
        if q[2] == p[2]:
            got = chk.translations_free(p[None], (q - p)[None, :2])[0]
        else:
            got = chk.rotations_free(p[None], [q[2] - p[2]])[0]
        d = step_clearance(L_SHAPE, p, q, obs, bounds)
        if abs(d - 0.1) > 2e-4:  # away from a graze, the two must agree
            assert got == (d >= 0.1), (p, q, d)
            seen[bool(got)] += 1
    assert seen[True] > 30 and seen[False] > 20


def test_lattice_states_are_free_exactly_when_the_polygon_clears_the_ring():
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    rng = np.random.default_rng(3)
    idx = np.argwhere(np.ones_like(cs.free))
    for k, iy, ix in idx[rng.choice(len(idx), 400, replace=False)]:
        pose = cs.lattice_pose(int(k), int(iy), int(ix))
        d = clearance(placed(L_SHAPE, pose), obstacles, BOUNDS)
        if abs(d - 2 * RADIUS) > 1e-9:
            assert cs.free[k, iy, ix] == (d > 2 * RADIUS), (pose, d)
    # the uncertain shell decided by the exact test is thin
    assert cs.counts["exact_checked"] < 0.35 * cs.counts["states"]


def test_moves_between_margin_free_states_need_no_test():
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    rng = np.random.default_rng(4)
    both = np.argwhere(cs.margin_free)
    checked = 0
    for k, iy, ix in both[rng.choice(len(both), 300, replace=False)]:
        mv = int(rng.integers(10))
        if mv < 8:
            k2, iy2, ix2 = k, iy + MOVES_8[mv][1], ix + MOVES_8[mv][0]
        else:
            k2, iy2, ix2 = (k + (1 if mv == 8 else -1)) % 12, iy, ix
        if not (0 <= iy2 < cs.frame.ny and 0 <= ix2 < cs.frame.nx and cs.margin_free[k2, iy2, ix2]):
            continue
        a = cs.lattice_pose(int(k), int(iy), int(ix))
        b = cs.lattice_pose(int(k2), int(iy2), int(ix2))
        assert step_clearance(L_SHAPE, a, b, obstacles, BOUNDS) >= 2 * RADIUS - 1e-9
        checked += 1
    assert checked > 100


def test_robot_cspace_grows_obstacles_by_the_disc():
    cs = build_robot_cspace(BOUNDS, [rect(1.5, 1.5, 2.5, 2.5)], 0.2, 0.05)
    xs, ys = cs.frame.centers()
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    d = geometry.polygon_signed_distance(pts, rect(1.5, 1.5, 2.5, 2.5)).reshape(gx.shape)
    free = ~cs.occupied
    assert np.all(d[free] >= 0.2 + 0.05 / math.sqrt(2) - 1e-9)  # a grid move keeps the radius
    assert np.all(free[(d > 0.3) & (gx > 0.3) & (gx < 3.7) & (gy > 0.3) & (gy < 3.7)])


# --------------------------------------------------------------------------- heuristics


def test_heuristic_ordering_and_skeleton_is_a_thin_midline():
    free = np.zeros((30, 60), dtype=bool)
    free[5:25, 2:58] = True
    free[5:22, 30] = False  # a wall with a gap at the top
    goal = (10, 50)
    eu = heuristics.euclid(free, goal, 0.1)
    oc = heuristics.octile(free.shape, goal, 0.1)
    wf = heuristics.wavefront(free, goal, 0.1)
    sk = heuristics.skeleton_wavefront(free, goal, 0.1)
    f = free
    assert np.all(oc[f] >= eu[f] - 1e-9) and np.all(wf[f] >= oc[f] - 1e-9)
    assert np.all(sk[f] >= wf[f] - 1e-9)
    assert wf[10, 10] > eu[10, 10] + 0.5  # the wall makes the wavefront longer
    assert sk[goal] == 0.0 and wf[goal] == 0.0
    skel = heuristics.zhang_suen_thin(free)
    assert skel.sum() < 0.2 * free.sum()
    assert not np.any(skel & ~free)
    corridor = np.zeros((11, 40), dtype=bool)
    corridor[2:9, 1:39] = True
    line = heuristics.zhang_suen_thin(corridor)
    assert set(np.nonzero(line[:, 10:30])[0]) <= {5}


def test_turn_bounds_match_a_brute_force_link_distance():
    from collections import deque

    rng = np.random.default_rng(5)
    free = rng.random((9, 12)) > 0.25
    goal = (4, 6)
    free[goal] = True
    t, v = heuristics.turn_bounds(free, goal, MOVES_8)
    mask = np.zeros_like(free)
    mask[goal] = True
    t2, v2 = heuristics.turn_bounds(free, mask, MOVES_8)
    assert np.array_equal(t, t2) and np.array_equal(v, v2)
    # brute force: 0-1 BFS backwards over (cell, last direction) from the goal
    ny, nx = free.shape
    best = {(goal[0], goal[1], d): 0 for d in range(8)}
    dq = deque((0, goal[0], goal[1], d) for d in range(8))
    while dq:
        k, y, x, d = dq.popleft()
        if k > best[(y, x, d)]:
            continue
        dx, dy = MOVES_8[d]
        py, px = y - dy, x - dx  # the cell that moved into (y, x) in direction d
        if not (0 <= py < ny and 0 <= px < nx and free[py, px]):
            continue
        for d0 in range(8):  # having last moved in d0 before
            k2 = k + (d0 != d)
            if k2 < best.get((py, px, d0), math.inf):
                best[(py, px, d0)] = k2
                (dq.appendleft if k2 == k else dq.append)((k2, py, px, d0))
    for d in range(8):
        for iy, ix in np.argwhere(free):
            assert t[d, iy, ix] == best.get((iy, ix, d), math.inf), (d, iy, ix)
    assert np.array_equal(v, t.min(axis=0))


def modal_dijkstra(free, seeds, kinds, step, turn, manip):
    """Brute force: Dijkstra backwards over (state, kind of last move), start kind free."""
    k_bins, ny, nx = free.shape
    start_kind = 10
    moves = [(d, (0, dy, dx), step * math.hypot(dx, dy)) for d, (dx, dy) in enumerate(MOVES_8)]
    moves += [(8, (1, 0, 0), turn), (8, (-1, 0, 0), turn)]
    # forward cost from (state, last kind) to the goal, computed by value iteration to a fixpoint
    cost: dict = {}
    for (k, y, x), c, f in zip(map(tuple, seeds[0]), seeds[1], kinds, strict=True):
        for m in range(11):
            charge = manip * (m != start_kind and f >= 0 and m != f)
            cost[(k, y, x, m)] = min(cost.get((k, y, x, m), math.inf), c + charge)
    heap = [(c, s) for s, c in cost.items()]
    heapq.heapify(heap)
    done = set()
    while heap:
        c, (k, y, x, m) = heapq.heappop(heap)
        if (k, y, x, m) in done:
            continue
        done.add((k, y, x, m))
        # predecessors: a state one move back, in any kind, that moved into (k, y, x) by kind m
        if m == start_kind:
            continue
        for d, (dk, dy, dx), w in moves:
            if d != m:
                continue
            pk, py, px = (k - dk) % k_bins, y - dy, x - dx
            if not (0 <= py < ny and 0 <= px < nx and free[pk, py, px]):
                continue
            for pm in range(11):
                if pm == 9:
                    continue
                c2 = c + w + manip * (pm != start_kind and pm != m)
                if c2 < cost.get((pk, py, px, pm), math.inf):
                    cost[(pk, py, px, pm)] = c2
                    heapq.heappush(heap, (c2, (pk, py, px, pm)))
    out = np.full(free.shape, np.inf)
    for (k, y, x, m), c in cost.items():
        if m == start_kind and free[k, y, x]:
            out[k, y, x] = c
    return out


@pytest.mark.parametrize("k_bins", [1, 4])
def test_lattice_cost_to_go_is_the_exact_cost_with_manipulations(k_bins):
    rng = np.random.default_rng(6 + k_bins)
    free = rng.random((k_bins, 7, 9)) > 0.2
    cells = np.argwhere(free)[rng.choice(free.sum(), 3, replace=False)]
    seeds = (cells, rng.uniform(0.0, 1.0, 3))
    kinds = np.array([-1, 2, 8 if k_bins > 1 else 5])
    want = modal_dijkstra(free, seeds, kinds, 0.5, 0.7, 2.0)
    got = heuristics.lattice_cost_to_go(free, seeds, 0.5, 0.7, 2.0, 100, kinds)
    fin = np.isfinite(want)
    assert np.array_equal(fin, np.isfinite(got))
    assert np.all(got[fin] <= want[fin] + 1e-12)  # a lower bound (float32 given back)
    assert np.allclose(got[fin], want[fin], rtol=1e-4)  # float32 rounds, their margin
    few = heuristics.lattice_cost_to_go(free, seeds, 0.5, 0.7, 2.0, 1, kinds)
    assert np.all(few[fin] <= want[fin] + 1e-12)  # fewer rounds: still a lower bound
    bare = heuristics.lattice_cost_to_go(free, seeds, 0.5, 0.7, 0.0)
    assert np.allclose(bare[fin], modal_dijkstra(free, seeds, kinds * 0 - 1, 0.5, 0.7, 0.0)[fin])


# --------------------------------------------------------------------------- the cases


def doorway_room(gap: float) -> list[np.ndarray]:
    """A 7 m x 5 m room cut by a wall at x = 3.4 m with one doorway ``gap`` m wide."""
    lo = 1.6
    return [rect(3.4, 0.0, 3.6, lo), rect(3.4, lo + gap, 3.6, 5.0)]


ROOM = np.array([[0.0, 0.0], [7.0, 5.0]])


def test_a_crate_passes_a_doorway_its_robots_fit():
    # a 1 m L crate with 0.1 m robots needs about 1.4 m: a 1.7 m doorway must be found at the
    # default 0.1 m (it used to be "different free regions"), and never be grazed
    obstacles = doorway_room(1.7)
    p = RouteSection()
    start, goal = (0.8, 2.0, 0.0), (5.4, 2.0, 0.0)
    res = plan_route(ROOM, obstacles, CRATE, 0.1, start, goal, p)
    assert res.ok, res.reason
    assert_route_clear(res, CRATE, 0.1, obstacles, ROOM, start, goal)
    # a doorway it does not fit is an answer, not a collision
    tight = doorway_room(1.25)
    res = plan_route(ROOM, tight, CRATE, 0.1, start, goal, p)
    assert res.status == "no_path" and "unreachable" in res.reason


@pytest.mark.parametrize("phi_deg", [23.0, 61.0])
def test_an_off_axis_doorway_one_cell_wider_than_the_ring_is_found(phi_deg):
    # resolution-complete in the sense: clearance one cell (0.1 m) beyond the ring on
    # each side, the doorway turned off the lattice's directions and heading bins
    phi = math.radians(phi_deg)
    room, c = np.array([[0.0, 0.0], [10.0, 10.0]]), np.array([5.0, 5.0])
    half = (1.0 + 2 * 0.2 + 2 * 0.1) / 2
    walls = [rect(-0.1, half, 0.1, 6.0), rect(-0.1, -6.0, 0.1, -half)]
    obstacles = [geometry.transform(w, (c[0], c[1], phi)) for w in walls]
    d = np.array([math.cos(phi), math.sin(phi)])
    centre = geometry.rot(phi) @ np.array([0.5, 0.5])
    start, goal = np.r_[c - 2.5 * d - centre, phi], np.r_[c + 2.5 * d - centre, phi]
    res = plan_route(room, obstacles, CRATE, 0.1, start, goal, RouteSection())
    assert res.ok, res.reason
    assert_route_clear(res, CRATE, 0.1, obstacles, room, start, goal)


def test_a_goal_near_a_wall_the_robots_fit_is_reached():
    # the object 0.3 m from the wall; the robots need 0.2 m
    start, goal = (1.0, 2.0, 0.0), (5.0, 0.3, 0.0)
    res = plan_route(ROOM, [], CRATE, 0.1, start, goal, RouteSection())
    assert res.ok, res.reason
    assert_route_clear(res, CRATE, 0.1, [], ROOM, start, goal)
    too_close = plan_route(ROOM, [], CRATE, 0.1, start, (5.0, 0.15, 0.0), RouteSection())
    assert too_close.status == "no_path"
    assert "goal pose collides" in too_close.reason and "walls" in too_close.reason


def test_one_heading_bin_turns_only_where_the_turn_is_free():
    # heading_bins = 1: a start at theta = pi beside a pillar used to give a first waypoint
    # inside the pillar and an uncosted half turn
    pillar = [rect(1.2, 0.6, 1.5, 1.0)]
    p = dataclasses.replace(PARAMS, heading_bins=1)
    start, goal = (0.9, 1.0, math.pi), (3.0, 3.0, 0.3)
    res = plan_route(BOUNDS, pillar, L_SHAPE, RADIUS, start, goal, p)
    assert res.ok, res.reason
    assert_route_clear(res, L_SHAPE, RADIUS, pillar, BOUNDS, start, goal)
    assert res.cost >= (math.pi + 0.3) / p.yaw_rate  # both turns are paid for
    steps = np.abs(geometry.wrap_angle(np.diff(res.waypoints[:, 2])))
    assert steps.max() <= math.pi / 4 + 1e-9  # no ambiguous half turn in one step


def test_the_final_turn_to_the_goal_heading_is_checked_and_costed():
    obstacles = wall_map()
    p = dataclasses.replace(PARAMS, manipulation_cost=1.5)
    start, goal = (0.8, 0.8, 0.0), (3.2, 0.8, 1.0)  # 1.0 rad lies between two of 12 bins
    res = plan_route(BOUNDS, obstacles, L_SHAPE, RADIUS, start, goal, p)
    assert res.ok, res.reason
    assert_route_clear(res, L_SHAPE, RADIUS, obstacles, BOUNDS, start, goal)
    wp = res.waypoints
    last = float(geometry.wrap_angle(wp[-1, 2] - wp[-2, 2]))
    assert 0 < abs(last) <= 2 * math.pi / 12 + 1e-9
    # every step is one straight move or one turn, and the cost is exactly what they take
    steps = np.diff(wp, axis=0)
    turn = np.abs(geometry.wrap_angle(steps[:, 2]))
    dist = np.where(turn > 1e-12, 0.0, np.linalg.norm(steps[:, :2], axis=1))
    expect = dist.sum() / p.speed + turn.sum() / p.yaw_rate + res.manipulations * 1.5
    assert res.cost == pytest.approx(expect, abs=1e-6)
    assert res.length_m == pytest.approx(dist.sum(), abs=1e-9)
    assert wp[:, 1].max() > 2.6  # over the wall's end
    assert res.manipulations >= 2


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(1, 5),
    kind=st.sampled_from(["cost_to_go", "euclid", "wavefront", "skeleton"]),
    wh=st.sampled_from([0.0, 1.0, 3.0]),
    k_bins=st.sampled_from([1, 5, 12]),
)
def test_a_route_never_brings_the_object_within_the_ring(seed, n, kind, wh, k_bins):
    rng = np.random.default_rng(seed)
    obstacles = []
    for _ in range(n):
        x, y = rng.uniform(0.3, 3.4, 2)
        w, h = rng.uniform(0.1, 0.8, 2)
        obstacles.append(rect(x, y, min(x + w, 3.9), min(y + h, 3.9)))
    p = dataclasses.replace(PARAMS, heuristic=kind, wh=wh, heading_bins=k_bins)
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, k_bins)
    start = np.r_[rng.uniform(0.3, 3.7, 2), rng.uniform(-math.pi, math.pi)]
    goal = np.r_[rng.uniform(0.3, 3.7, 2), rng.uniform(-math.pi, math.pi)]
    res = plan_route(None, None, None, None, start, goal, p, cspace=cs)
    if not res.ok:
        assert res.status == "no_path" and res.reason and math.isinf(res.cost)
        return
    assert_route_clear(res, L_SHAPE, RADIUS, obstacles, BOUNDS, start, goal)


# --------------------------------------------------------------------------- the search


def test_the_default_heuristic_is_optimal_and_expands_little():
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    start, goal = (0.8, 0.8, 0.0), (3.2, 1.0, 2.0)

    def run(**kw):
        return plan_route(None, None, None, None, start, goal,
                          dataclasses.replace(PARAMS, **kw), cspace=cs)  # fmt: skip

    dijkstra = run(wh=0.0)
    best = run()
    assert best.ok and dijkstra.ok
    assert best.cost == pytest.approx(dijkstra.cost, rel=1e-9)
    assert best.expanded < 3 * len(best.waypoints) < dijkstra.expanded
    for kind in ("euclid", "wavefront"):  # the paper's admissible potentials: optimal, slower
        r = run(heuristic=kind)
        assert r.cost == pytest.approx(dijkstra.cost, rel=1e-9)
        assert r.expanded > best.expanded
    skel = run(heuristic="skeleton")
    assert skel.ok and skel.cost >= dijkstra.cost - 1e-9
    # greedy never re-opens a state; weighted A* only when asked to
    assert run(wg=0.0).reexpanded == 0
    assert run(heuristic="wavefront", wh=3.0).reexpanded == 0
    again = run(heuristic="wavefront", wh=3.0, reopen=True)
    assert again.cost <= run(heuristic="wavefront", wh=3.0).cost + 1e-9


def test_pathmax_keeps_f_non_decreasing_with_an_inconsistent_heuristic():
    frame = GridFrame.over([[0, 0], [3, 3]], 0.1)
    occ = np.zeros((30, 30), dtype=bool)
    occ[5:25, 15] = True
    roadmap = RobotRoadmap(RobotCSpace.from_occupancy(occ, frame))
    exact = roadmap.heuristic_table("wavefront", (15, 25))
    rng = np.random.default_rng(0)
    noisy = exact * rng.uniform(0.0, 1.0, exact.shape)  # admissible, badly inconsistent
    kw = dict(h_table=noisy, trace=True)
    with_pm = roadmap.plan((0.5, 1.5), (2.55, 1.55), pathmax=True, **kw)
    without = roadmap.plan((0.5, 1.5), (2.55, 1.55), pathmax=False, **kw)
    assert with_pm.ok and without.ok
    assert np.all(np.diff(with_pm.f_trace) >= -1e-12)
    assert np.any(np.diff(without.f_trace) < -1e-6)  # the property is not vacuous
    assert with_pm.cost == pytest.approx(roadmap.plan((0.5, 1.5), (2.55, 1.55)).cost)
    cs = build_object_cspace(BOUNDS, wall_map(), L_SHAPE, RADIUS, 0.1, 12)
    p = dataclasses.replace(PARAMS, heuristic="skeleton")
    res = plan_route(
        None, None, None, None, (0.8, 0.8, 0.0), (3.2, 1.0, 2.0), p, cspace=cs, trace=True
    )
    assert res.ok and np.all(np.diff(res.f_trace) >= -1e-12)
    assert len(res.f_trace) == res.expanded


def test_no_path_answers_say_why():
    box = [rect(2.4, 2.4, 3.6, 2.5), rect(2.4, 3.5, 3.6, 3.6), rect(2.4, 2.4, 2.5, 3.6)]
    box.append(rect(3.5, 2.4, 3.6, 3.6))
    small = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    p = PARAMS
    res = plan_route(BOUNDS, box, small, 0.02, (0.8, 0.8, 0.0), (3.0, 3.0, 0.0), p)
    assert res.status == "no_path" and "unreachable" in res.reason
    assert not res.ok and math.isinf(res.cost) and res.to_dict()["cost"] is None
    rob = plan_robot_route(BOUNDS, box, 0.05, (0.5, 0.5), (3.0, 3.0), 0.05)
    assert rob.status == "no_path" and "unreachable" in rob.reason
    out = plan_route(BOUNDS, box, small, 0.02, (0.8, 0.8, 0.0), (5.0, 3.0, 0.0), p)
    assert out.status == "no_path" and "outside" in out.reason
    hit = plan_route(BOUNDS, box, small, 0.02, (2.45, 3.0, 0.0), (1.0, 1.0, 0.0), p)
    assert hit.status == "no_path" and "start pose collides" in hit.reason
    assert "obstacles[" in hit.reason
    capped = plan_route(
        BOUNDS, [], small, 0.02, (0.5, 0.5, 0.0), (3.5, 3.5, 1.0),
        dataclasses.replace(p, heuristic="euclid"), max_expanded=10,
    )  # fmt: skip
    assert capped.status == "no_path" and "limit" in capped.reason


def test_a_planner_built_once_replans_from_new_starts():
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    goal = (3.2, 1.0, 2.0)
    planner = RoutePlanner(cs, goal, PARAMS)
    table = planner._h_obj
    starts = [(0.8, 0.8, 0.0), (1.2, 3.0, 1.0), (0.83, 1.41, -0.4)]
    for s in starts:
        res = planner.plan(s)
        fresh = plan_route(BOUNDS, obstacles, L_SHAPE, RADIUS, s, goal, PARAMS)
        assert res.ok and res.cost == pytest.approx(fresh.cost, rel=1e-12)
        assert np.allclose(res.waypoints, fresh.waypoints)
        assert res.expanded < 3 * len(res.waypoints)
        # the object strays from the route: plan again from where it is
        mid = res.waypoints[len(res.waypoints) // 2] + np.array([0.03, -0.02, 0.05])
        if cs.is_free(mid):
            again = planner.plan(mid)
            assert again.ok and again.cost <= res.cost
            assert_route_clear(again, L_SHAPE, RADIUS, obstacles, BOUNDS, mid, goal)
    assert planner._h_obj is table  # one table for every plan toward this goal


def test_identical_inputs_give_identical_results():
    p = dataclasses.replace(PARAMS, manipulation_cost=1.0)
    a = plan_route(BOUNDS, wall_map(), L_SHAPE, RADIUS, (0.8, 0.8, 0.0), (3.2, 1.0, 2.0), p)
    b = plan_route(BOUNDS, wall_map(), L_SHAPE, RADIUS, (0.8, 0.8, 0.0), (3.2, 1.0, 2.0), p)
    assert a.ok
    assert np.array_equal(a.waypoints, b.waypoints) and np.array_equal(a.subgoals, b.subgoals)
    assert (a.cost, a.expanded, a.generated, a.manipulations) == (
        b.cost,
        b.expanded,
        b.generated,
        b.manipulations,
    )


def test_subgoals_are_where_the_kind_of_move_changes():
    p = dataclasses.replace(PARAMS, subgoal_spacing=100.0)
    start, goal = (0.8, 0.8, 0.0), (3.2, 1.0, 2.0)
    res = plan_route(BOUNDS, wall_map(), L_SHAPE, RADIUS, start, goal, p)
    wp = res.waypoints
    kinds = []
    for a, b in zip(wp[:-1], wp[1:], strict=True):
        if abs(geometry.wrap_angle(b[2] - a[2])) > 1e-12:
            kinds.append("turn")
        else:
            d = (b[:2] - a[:2]) / np.linalg.norm(b[:2] - a[:2])
            kinds.append((round(d[0], 6), round(d[1], 6)))
    changes = [i for i in range(1, len(kinds)) if kinds[i] != kinds[i - 1]]
    want = np.vstack([wp[changes], wp[-1:]])
    assert np.allclose(res.subgoals, want)
    spaced = plan_route(BOUNDS, wall_map(), L_SHAPE, RADIUS, start, goal, PARAMS)
    gaps = np.linalg.norm(np.diff(np.vstack([wp[:1], spaced.subgoals])[:, :2], axis=0), axis=1)
    assert gaps.max() <= PARAMS.subgoal_spacing + 0.15
    assert res.lateral_deviation(wp[3, :2]) == pytest.approx(0.0, abs=1e-12)
    assert res.lateral_deviation(wp[3, :2] + [0.0, 5.0]) > 0.5


def test_robot_route_is_optimal_on_its_grid_and_reusable():
    obstacles = [rect(1.9, 0.0, 2.1, 3.0)]
    roadmap = RobotRoadmap.build(BOUNDS, obstacles, 0.1, 0.05, speed=0.5)
    res = roadmap.plan((0.5, 0.5), (3.5, 0.5))
    assert res.heuristic == "landmarks"
    again = plan_robot_route(BOUNDS, obstacles, 0.1, (0.5, 0.5), (3.5, 0.5), 0.05, roadmap=roadmap)
    assert res.ok and np.array_equal(res.waypoints, again.waypoints)
    assert res.waypoints[:, 1].max() > 3.0
    gc = roadmap.cspace.frame.cell_of((3.5, 0.5))
    sc = roadmap.cspace.frame.cell_of((0.5, 0.5))
    exact = roadmap.heuristic_table("wavefront", gc)[sc] / 0.5  # csgraph Dijkstra
    assert res.cost == pytest.approx(exact, rel=1e-9)
    for q in res.waypoints:
        assert roadmap.cspace.is_free(q[:2])
        assert geometry.polygon_signed_distance([q[:2]], obstacles[0])[0] >= 0.1
    runs = {k: roadmap.plan((0.5, 0.5), (3.5, 0.5), heuristic=k) for k in ROBOT_HEURISTICS}
    for k in ("octile", "euclid", "wavefront"):  # admissible: the same optimal cost
        assert runs[k].cost == pytest.approx(res.cost, rel=1e-12)
    assert runs["wavefront"].expanded <= res.expanded < runs["octile"].expanded
    assert runs["octile"].expanded <= runs["euclid"].expanded
    # the landmark bound lies between the octile distance and the true distance
    exact = roadmap.heuristic_table("wavefront", gc)
    alt = roadmap.heuristic_table("landmarks", gc)
    free = ~roadmap.cspace.occupied
    octile = roadmap.heuristic_table("octile", gc)
    assert np.all(alt[free] <= exact[free] + 1e-9) and np.all(alt[free] >= octile[free] - 1e-12)


def test_shipped_map_parses_with_four_reachable_goals():
    from controller.planning.route_maps import load_route_map

    m = load_route_map("yamashita")
    assert [n for n, _ in m.goals] == ["Goal1", "Goal2", "Goal3", "Goal4"]
    assert np.allclose(m.bounds, [[0, 0], [12.8, 12.8]])
    cs = build_object_cspace(m.bounds, list(m.obstacles), m.footprint, m.robot_radius, 0.1, 36)
    assert cs.free.shape == (36, 128, 128)
    s = cs.cell_of(m.start)
    assert cs.is_free(m.start)
    assert all(cs.is_free(g) for _, g in m.goals)
    assert all(cs.labels[cs.cell_of(g)] == cs.labels[s] for _, g in m.goals)
