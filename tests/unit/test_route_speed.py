"""The fast object search is the reference search, only faster (issue 23 item 7).

``RoutePlanner.plan`` runs a specialised search loop (``_FastSearch``); ``plan(...,
reference=True)`` runs the generic ``weighted_astar`` over ``_ObjectMoves``, the loop it
replaced. Same f = w_g g + w_h h with pathmax, same tie-breaking, moves, costs and pruning: so
on every seeded case the two must agree exactly: status, cost, waypoints, every search count
and the f of every expansion, also over re-plans from one planner (whose caches persist).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from controller.config import RouteSection
from controller.planning.cspace import build_object_cspace
from controller.planning.route import RoutePlanner

L_SHAPE = np.array(
    [[-0.2, -0.15], [0.2, -0.15], [0.2, 0.0], [-0.05, 0.0], [-0.05, 0.15], [-0.2, 0.15]]
)
BOUNDS = np.array([[0.0, 0.0], [4.0, 4.0]])
RADIUS = 0.05


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def random_case(seed: int, k_bins: int):
    """Seeded obstacles (rectangles), a start and two goals-side poses on a 4 m room."""
    rng = np.random.default_rng(seed)
    obstacles = []
    for _ in range(int(rng.integers(2, 7))):
        x, y = rng.uniform(0.3, 3.4, 2)
        w, h = rng.uniform(0.1, 1.2, 2)
        obstacles.append(rect(x, y, min(x + w, 3.9), min(y + h, 3.9)))
    poses = [np.r_[rng.uniform(0.3, 3.7, 2), rng.uniform(-math.pi, math.pi)] for _ in range(3)]
    return obstacles, poses


def same(a, b) -> None:
    assert a.status == b.status and a.reason == b.reason
    assert a.cost == b.cost
    assert (a.expanded, a.generated, a.reexpanded) == (b.expanded, b.generated, b.reexpanded)
    assert a.manipulations == b.manipulations
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    np.testing.assert_array_equal(a.f_trace, b.f_trace)


CASES = [
    # (heuristic, wg, wh, reopen, heading bins)
    ("cost_to_go", 1.0, 1.0, False, 12),
    ("cost_to_go", 1.0, 1.0, False, 1),
    ("cost_to_go", 1.0, 3.0, True, 8),
    ("euclid", 1.0, 1.0, False, 12),
    ("wavefront", 1.0, 0.5, False, 8),
    ("wavefront", 0.0, 1.0, False, 12),
    ("skeleton", 1.0, 1.0, False, 12),
    ("skeleton", 1.0, 2.0, True, 5),
    ("skeleton", 1.0, 0.0, False, 2),
]


@pytest.mark.parametrize("kind, wg, wh, reopen, k_bins", CASES)
@pytest.mark.parametrize("seed", [3, 17, 2026])
def test_fast_search_matches_the_reference_on_seeded_maps(kind, wg, wh, reopen, k_bins, seed):
    obstacles, poses = random_case(seed, k_bins)
    params = RouteSection(
        resolution=0.1, heading_bins=k_bins, heuristic=kind, wg=wg, wh=wh, reopen=reopen
    )
    goal = poses[0]
    # each side its own C-space and planner, so no cache is shared; two plans from each (the
    # second re-uses the planner's memo and move caches, as a re-plan does)
    runs = []
    for reference in (True, False):
        cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, k_bins)
        planner = RoutePlanner(cs, goal, params)
        runs.append([planner.plan(s, reference=reference, trace=True) for s in poses[1:]])
    for a, b in zip(*runs, strict=True):
        same(a, b)


def test_fast_search_matches_the_reference_on_the_shipped_map_and_counts_pathmax_off():
    from controller.planning.route_maps import load_route_map

    m = load_route_map("yamashita")
    p = RouteSection(resolution=0.2, heading_bins=12)
    cs = build_object_cspace(m.bounds, list(m.obstacles), m.footprint, m.robot_radius, 0.2, 12)
    found = 0
    for kind in ("cost_to_go", "skeleton"):
        params = dataclasses.replace(p, heuristic=kind)
        for _, goal in m.goals:
            planner = RoutePlanner(cs, goal, params)
            ref = planner.plan(m.start, reference=True, pathmax=False)
            fast = RoutePlanner(cs, goal, params).plan(m.start, pathmax=False)
            same(ref, fast)
            found += ref.ok
    assert found == 8


def test_the_expansion_limit_stops_both_alike():
    obstacles, poses = random_case(5, 12)
    params = RouteSection(resolution=0.1, heading_bins=12, heuristic="euclid")
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    ref = RoutePlanner(cs, poses[0], params).plan(poses[1], reference=True, max_expanded=40)
    fast = RoutePlanner(cs, poses[0], params).plan(poses[1], max_expanded=40)
    same(ref, fast)
    assert fast.status == "no_path" and "limit of 40" in fast.reason


def _full_trail_distance(ch, p, v):
    """The sweep distance of a translation over every (vertex, edge) pair (the formula of
    before the pair filter)."""
    from controller.planning.cspace import segment_distance

    w = ch.world(p)
    sa, sb = ch.seg_a, ch.seg_b
    d = segment_distance(w[:, :, None], (w + v[:, None])[:, :, None], sa[None, None], sb)
    d = d.reshape(len(p), -1).min(axis=1)
    fa, fb = w[:, None], np.roll(w, -1, axis=1)[:, None]
    o0 = np.broadcast_to(ch.verts[None, :, None], (len(p), len(ch.verts), 1, 2))
    d2 = segment_distance(o0, o0 - v[:, None, None], fa, fb)
    return np.minimum(d, d2.reshape(len(p), -1).min(axis=1))


def _full_arc_distance(ch, p, dt):
    from controller.planning.cspace import arc_segment_distance

    c = p[:, None, None, :2]
    sa, sb = ch.seg_a, ch.seg_b
    start = (p[:, 2:3] + ch._polar[None])[:, :, None]
    d = arc_segment_distance(c, ch._radius[None, :, None], start, dt[:, None, None],
                             sa[None, None], sb)  # fmt: skip
    d = d.reshape(len(p), -1).min(axis=1)
    w = ch.world(p)
    fa, fb = w[:, None], np.roll(w, -1, axis=1)[:, None]
    rel = ch.verts[None] - p[:, None, :2]
    rad = np.linalg.norm(rel, axis=-1)[..., None]
    ang = np.arctan2(rel[..., 1], rel[..., 0])[..., None]
    d2 = arc_segment_distance(c, rad, ang, -dt[:, None, None], fa, fb)
    return np.minimum(d, d2.reshape(len(p), -1).min(axis=1))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_pair_filtered_sweep_tests_answer_as_the_full_formula(seed):
    """The sweep tests only compute the (vertex, edge) pairs whose boxes come within the ring:
    on free poses near obstacles (where the answers are mixed), every answer is the full
    formula's, for translations and for turns of up to half a circle either way."""
    obstacles, _ = random_case(seed, 12)
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    ch = cs.checker
    free = np.argwhere(cs.free & ~cs.margin_free)
    rng = np.random.default_rng(seed)
    pick = free[rng.choice(len(free), size=min(400, len(free)), replace=False)]
    xs, ys = cs.frame.centers()
    poses = np.stack([xs[pick[:, 2]], ys[pick[:, 1]], pick[:, 0] * cs.step], 1)
    poses[:, :2] += rng.uniform(-0.05, 0.05, (len(poses), 2))
    steps = rng.uniform(-0.15, 0.15, (len(poses), 2))
    turns = rng.uniform(-math.pi, math.pi, len(poses))
    req = ch.req - 1e-12
    got_t, got_r = ch.translations_free(poses, steps), ch.rotations_free(poses, turns)
    np.testing.assert_array_equal(got_t, _full_trail_distance(ch, poses, steps) >= req)
    np.testing.assert_array_equal(got_r, _full_arc_distance(ch, poses, turns) >= req)
    assert 0 < got_t.sum() < len(poses) and 0 < got_r.sum() < len(poses)  # mixed answers
