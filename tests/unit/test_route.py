"""Global route planning: C-space, heuristics, weighted A* with pathmax, robot routes, CLI."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controller import geometry
from controller.cli import main
from controller.config import RouteSection
from controller.planning import heuristics
from controller.planning.cspace import (
    GridFrame,
    RobotCSpace,
    build_object_cspace,
    build_robot_cspace,
)
from controller.planning.roadmap import RobotRoadmap, plan_robot_route
from controller.planning.route import object_heuristic, plan_route

L_SHAPE = np.array(
    [[-0.2, -0.15], [0.2, -0.15], [0.2, 0.0], [-0.05, 0.0], [-0.05, 0.15], [-0.2, 0.15]]
)
BOUNDS = np.array([[0.0, 0.0], [4.0, 4.0]])
PARAMS = RouteSection(resolution=0.1, heading_bins=12, heuristic="euclid", wg=1.0, wh=1.0)
RADIUS = 0.05


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def wall_map() -> list[np.ndarray]:
    """A wall across the middle with one gap: the object must go round."""
    return [rect(1.9, 0.0, 2.1, 2.4), rect(0.0, 3.4, 0.6, 4.0)]


def grown_footprint(pose: np.ndarray, radius: float) -> shapely.Geometry:
    return shapely.Polygon(geometry.transform(L_SHAPE, pose)).buffer(2 * radius)


def footprint_hits(pose, obstacles, radius=RADIUS, bounds=BOUNDS) -> bool:
    fp = grown_footprint(pose, radius)
    room = shapely.box(*bounds[0], *bounds[1])
    if not room.contains(fp):
        return True
    return any(fp.intersects(shapely.Polygon(o)) for o in obstacles)


# --------------------------------------------------------------------------- C-space


def test_free_cells_are_collision_free_for_an_asymmetric_footprint():
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    rng = np.random.default_rng(3)
    free = np.argwhere(cs.free)
    assert len(free) > 1000
    xs, ys = cs.frame.centers()
    for k, iy, ix in free[rng.choice(len(free), 300, replace=False)]:
        pose = np.array([xs[ix], ys[iy], cs.heading_of(int(k))])
        assert not footprint_hits(pose, obstacles), pose
    # and it is not absurdly conservative: most poses clear by 0.25 m are free
    occ = np.argwhere(cs.occupied)
    clear = 0
    for k, iy, ix in occ[rng.choice(len(occ), 300, replace=False)]:
        pose = np.array([xs[ix], ys[iy], cs.heading_of(int(k))])
        fp = grown_footprint(pose, RADIUS + 0.25)
        room = shapely.box(0, 0, 4, 4)
        if room.contains(fp) and not any(fp.intersects(shapely.Polygon(o)) for o in obstacles):
            clear += 1
    assert clear == 0


def test_robot_cspace_grows_obstacles_by_the_disc():
    cs = build_robot_cspace(BOUNDS, [rect(1.5, 1.5, 2.5, 2.5)], 0.2, 0.05)
    xs, ys = cs.frame.centers()
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    d = geometry.polygon_signed_distance(pts, rect(1.5, 1.5, 2.5, 2.5)).reshape(gx.shape)
    free = ~cs.occupied
    assert np.all(d[free] >= 0.2)  # never closer than the radius
    assert np.all(free[(d > 0.35) & (gx > 0.35) & (gx < 3.65) & (gy > 0.35) & (gy < 3.65)])


# --------------------------------------------------------------------------- heuristics


def test_heuristic_ordering_and_skeleton_is_a_thin_midline():
    free = np.zeros((30, 60), dtype=bool)
    free[5:25, 2:58] = True
    free[5:22, 30] = False  # a wall with a gap at the top
    goal = (10, 50)
    eu = heuristics.euclid(free, goal, 0.1)
    wf = heuristics.wavefront(free, goal, 0.1)
    sk = heuristics.skeleton_wavefront(free, goal, 0.1)
    f = free
    assert np.all(wf[f] >= eu[f] - 1e-9)
    assert np.all(sk[f] >= wf[f] - 1e-9)
    assert wf[10, 10] > eu[10, 10] + 0.5  # the wall makes the wavefront longer
    assert sk[goal] == 0.0 and wf[goal] == 0.0
    skel = heuristics.zhang_suen_thin(free)
    assert skel.sum() < 0.2 * free.sum()
    assert not np.any(skel & ~free)
    # a straight corridor thins to a line along its middle
    corridor = np.zeros((11, 40), dtype=bool)
    corridor[2:9, 1:39] = True
    line = heuristics.zhang_suen_thin(corridor)
    assert set(np.nonzero(line[:, 10:30])[0]) <= {5}


def test_turn_bounds_match_a_brute_force_link_distance():
    from collections import deque

    from controller.planning.cspace import MOVES_8

    rng = np.random.default_rng(5)
    free = rng.random((9, 12)) > 0.25
    goal = (4, 6)
    free[goal] = True
    t, v = heuristics.turn_bounds(free, goal, MOVES_8)
    ny, nx = free.shape
    # 0-1 BFS backwards is fiddly; search forward from every state instead (tiny grid)
    for d in range(8):
        for iy, ix in np.argwhere(free):
            best = {(iy, ix, d): 0}
            dq = deque([(0, iy, ix, d)])
            found = math.inf
            while dq:
                k, y, x, dd = dq.popleft()
                if k > best.get((y, x, dd), math.inf):
                    continue
                if (y, x) == goal:
                    found = min(found, k)
                    continue
                for d2, (dx, dy) in enumerate(MOVES_8):
                    y2, x2 = y + dy, x + dx
                    if 0 <= y2 < ny and 0 <= x2 < nx and free[y2, x2]:
                        k2 = k + (d2 != dd)
                        if k2 < best.get((y2, x2, d2), math.inf):
                            best[(y2, x2, d2)] = k2
                            (dq.appendleft if k2 == k else dq.append)((k2, y2, x2, d2))
            assert t[d, iy, ix] == found, (d, iy, ix)
    assert np.array_equal(v, t.min(axis=0))


# --------------------------------------------------------------------------- the search


def test_route_goes_round_the_wall_and_accounts_its_cost():
    obstacles = wall_map()
    p = dataclasses.replace(PARAMS, manipulation_cost=1.5)
    res = plan_route(BOUNDS, obstacles, L_SHAPE, RADIUS, (0.8, 0.8, 0.0), (3.2, 0.8, 1.0), p)
    assert res.ok, res.reason
    wp = res.waypoints
    assert np.allclose(wp[0], (0.8, 0.8, 0.0)) and np.allclose(wp[-1], (3.2, 0.8, 1.0))
    assert wp[:, 1].max() > 2.6  # over the wall's end
    assert np.allclose(res.subgoals[-1], wp[-1])
    # cost = distance / speed + rotation / yaw_rate + manipulation cost per re-arrangement
    inner = wp[1:-1]
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    snapped = np.array(
        [[*cs.frame.center(*cs.cell_of(q)[1:]), cs.heading_of(cs.cell_of(q)[0])] for q in wp]
    )
    steps = np.diff(snapped, axis=0)
    dist = np.linalg.norm(steps[:, :2], axis=1)
    turn = np.abs(geometry.wrap_angle(steps[:, 2]))
    assert np.all((dist > 0) != (turn > 1e-9))  # each step is a move or a turn, not both
    assert np.all(dist <= 0.1 * math.sqrt(2) + 1e-9)
    expect = dist.sum() / p.speed + turn.sum() / p.yaw_rate + res.manipulations * 1.5
    assert res.cost == pytest.approx(expect, abs=1e-6)
    assert len(inner) > 10
    # subgoals (with no spacing cuts) are exactly where the kind of move changes
    far = plan_route(
        BOUNDS, obstacles, L_SHAPE, RADIUS, (0.8, 0.8, 0.0), (3.2, 0.8, 1.0),
        dataclasses.replace(p, subgoal_spacing=100.0),
    )  # fmt: skip
    kinds = [
        (round(float(dx), 6), round(float(dy), 6)) if abs(dt) < 1e-9 else "turn"
        for dx, dy, dt in steps
    ]
    changes = [i for i in range(1, len(kinds)) if kinds[i] != kinds[i - 1]]
    want = np.vstack([snapped[changes], snapped[-1:]])
    got = np.array(
        [
            [*cs.frame.center(*cs.cell_of(q)[1:]), cs.heading_of(cs.cell_of(q)[0])]
            for q in far.subgoals
        ]
    )
    assert np.allclose(got, want)
    assert res.manipulations == len(changes)  # every change after the first move is paid for


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(1, 6),
    kind=st.sampled_from(["euclid", "wavefront", "skeleton"]),
    wh=st.sampled_from([0.0, 0.5, 1.0, 3.0]),
)
def test_path_never_enters_an_occupied_cell(seed, n, kind, wh):
    rng = np.random.default_rng(seed)
    obstacles = []
    for _ in range(n):
        x, y = rng.uniform(0.3, 3.4, 2)
        w, h = rng.uniform(0.1, 0.8, 2)
        obstacles.append(rect(x, y, min(x + w, 3.9), min(y + h, 3.9)))
    p = dataclasses.replace(PARAMS, heuristic=kind, wh=wh, heading_bins=8, resolution=0.1)
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 8)
    free_cells = np.argwhere(cs.free)
    if len(free_cells) < 2:
        return
    xs, ys = cs.frame.centers()
    a, b = free_cells[rng.choice(len(free_cells), 2, replace=False)]
    start = (xs[a[2]], ys[a[1]], cs.heading_of(int(a[0])))
    goal = (xs[b[2]], ys[b[1]], cs.heading_of(int(b[0])))
    res = plan_route(None, None, None, None, start, goal, p, cspace=cs)
    connected = cs.labels[tuple(a)] == cs.labels[tuple(b)]
    assert res.ok == connected, res.reason
    if not res.ok:
        assert res.status == "no_path" and res.reason
        return
    for q in res.waypoints:
        assert cs.is_free(q), q
        assert not footprint_hits(q, obstacles), q


@pytest.mark.parametrize("kind", ["euclid", "wavefront"])
def test_admissible_astar_cost_equals_dijkstra(kind):
    obstacles = wall_map()
    cs = build_object_cspace(BOUNDS, obstacles, L_SHAPE, RADIUS, 0.1, 12)
    start, goal = (0.8, 0.8, 0.0), (3.2, 1.0, 2.0)
    base = dataclasses.replace(PARAMS, heuristic=kind)
    astar = plan_route(None, None, None, None, start, goal, base, cspace=cs)
    dijkstra = plan_route(
        None, None, None, None, start, goal, dataclasses.replace(base, wh=0.0), cspace=cs
    )
    assert astar.ok and dijkstra.ok
    assert astar.cost == pytest.approx(dijkstra.cost, rel=1e-12)
    assert astar.expanded < dijkstra.expanded
    greedy = plan_route(
        None, None, None, None, start, goal, dataclasses.replace(base, wg=0.0), cspace=cs
    )
    assert greedy.ok and greedy.cost >= dijkstra.cost - 1e-9
    bare = plan_route(None, None, None, None, start, goal, base, cspace=cs, turn_bound=False)
    assert bare.cost == pytest.approx(dijkstra.cost, rel=1e-12)
    assert astar.expanded < bare.expanded < dijkstra.expanded


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
    # object search with the (inconsistent) skeleton heuristic
    cs = build_object_cspace(BOUNDS, wall_map(), L_SHAPE, RADIUS, 0.1, 12)
    p = dataclasses.replace(PARAMS, heuristic="skeleton")
    res = plan_route(
        None, None, None, None, (0.8, 0.8, 0.0), (3.2, 1.0, 2.0), p, cspace=cs, trace=True
    )
    assert res.ok and np.all(np.diff(res.f_trace) >= -1e-12)
    assert len(res.f_trace) == res.expanded


def test_enclosed_goal_returns_no_path():
    box = [rect(2.4, 2.4, 3.6, 2.5), rect(2.4, 3.5, 3.6, 3.6), rect(2.4, 2.4, 2.5, 3.6)]
    box.append(rect(3.5, 2.4, 3.6, 3.6))
    p = dataclasses.replace(PARAMS, heuristic="euclid")
    small = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    res = plan_route(BOUNDS, box, small, 0.02, (0.8, 0.8, 0.0), (3.0, 3.0, 0.0), p)
    assert res.status == "no_path" and "unreachable" in res.reason
    assert not res.ok and math.isinf(res.cost) and res.to_dict()["cost"] is None
    rob = plan_robot_route(BOUNDS, box, 0.05, (0.5, 0.5), (3.0, 3.0), 0.05)
    assert rob.status == "no_path" and "unreachable" in rob.reason
    out = plan_route(BOUNDS, box, small, 0.02, (0.8, 0.8, 0.0), (5.0, 3.0, 0.0), p)
    assert out.status == "no_path" and "outside" in out.reason
    hit = plan_route(BOUNDS, box, small, 0.02, (2.45, 3.0, 0.0), (1.0, 1.0, 0.0), p)
    assert hit.status == "no_path" and "collides" in hit.reason
    capped = plan_route(
        BOUNDS, [], small, 0.02, (0.5, 0.5, 0.0), (3.5, 3.5, 1.0), p, max_expanded=10
    )
    assert capped.status == "no_path" and "limit" in capped.reason


def test_identical_inputs_give_identical_results():
    p = dataclasses.replace(PARAMS, heuristic="skeleton", manipulation_cost=1.0)
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


def test_reused_cspace_and_heuristic_table_give_the_same_route():
    cs = build_object_cspace(BOUNDS, wall_map(), L_SHAPE, RADIUS, 0.1, 12)
    goal = (3.2, 1.0, 2.0)
    c = cs.cell_of(goal)
    table = object_heuristic(cs, "wavefront", (c[1], c[2]))
    p = dataclasses.replace(PARAMS, heuristic="wavefront")
    fresh = plan_route(BOUNDS, wall_map(), L_SHAPE, RADIUS, (0.8, 0.8, 0.0), goal, p)
    reused = plan_route(None, None, None, None, (0.8, 0.8, 0.0), goal, p, cspace=cs, h_table=table)
    assert np.array_equal(fresh.waypoints, reused.waypoints)
    with pytest.raises(ValueError, match="heading"):
        plan_route(
            None,
            None,
            None,
            None,
            (0.8, 0.8, 0.0),
            goal,
            dataclasses.replace(p, heading_bins=8),
            cspace=cs,
        )


def test_robot_route_is_optimal_on_its_grid_and_reusable():
    obstacles = [rect(1.9, 0.0, 2.1, 3.0)]
    roadmap = RobotRoadmap.build(BOUNDS, obstacles, 0.1, 0.05, speed=0.5)
    res = roadmap.plan((0.5, 0.5), (3.5, 0.5))
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
    wave = roadmap.plan((0.5, 0.5), (3.5, 0.5), heuristic="wavefront")
    assert wave.cost == pytest.approx(res.cost) and wave.expanded <= res.expanded


# --------------------------------------------------------------------------- CLI


KEYS = {"status", "waypoints", "subgoals", "cost", "length_m", "expanded", "seconds"}
KEYS |= {"heuristic", "wg", "wh"}

MAP_TOML = """
[map]
name = "tiny"
robot_radius = 0.05
[world]
bounds = [[0.0, 0.0], [4.0, 4.0]]
[object]
polygon = [[-0.2, -0.1], [0.2, -0.1], [0.2, 0.1], [-0.2, 0.1]]
start = [0.8, 0.8, 0.0]
[[goals]]
name = "open"
pose = [3.2, 0.8, 0.0]
[[goals]]
name = "boxed"
pose = [3.0, 3.0, 0.0]
{boxes}
"""


def _map_file(tmp_path) -> str:
    boxes = "".join(
        f"[[obstacles]]\npolygon = {rect(*r).tolist()}\n"
        for r in (
            (2.3, 2.3, 3.7, 2.4),
            (2.3, 3.6, 3.7, 3.7),
            (2.3, 2.3, 2.4, 3.7),
            (3.6, 2.3, 3.7, 3.7),
        )
    )
    path = tmp_path / "tiny.toml"
    path.write_text(MAP_TOML.replace("{boxes}", boxes))
    return str(path)


def test_cli_json_fields_and_exit_codes(tmp_path, capsys):
    f = _map_file(tmp_path)
    rc = main(["plan", "route", "--map", f, "--goal", "1", "--heuristic", "wavefront", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and set(out) == KEYS
    assert out["status"] == "ok" and out["heuristic"] == "wavefront" and out["wg"] == 1.0
    assert len(out["waypoints"][0]) == 3 and out["cost"] > 0 and out["expanded"] > 0
    rc = main(["plan", "route", "--map", f, "--goal", "boxed", "--wh", "0.5", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 1 and out["status"] == "no_path" and out["cost"] is None and out["wh"] == 0.5
    assert main(["plan", "route", "--map", f, "--goal", "7", "--json"]) == 2
    assert main(["plan", "route", "--map", str(tmp_path / "nope.toml")]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["plan", "route", "--map", f, "--wg", "0.5"])
    assert exc.value.code == 2


def test_cli_plans_the_fleet_config_and_plots(tmp_path, capsys):
    png = tmp_path / "route.png"
    rc = main(["plan", "route", "--config", "fleet.toml", "--heuristic", "wavefront",
               "--json", "--plot", str(png)])  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["status"] == "ok" and png.stat().st_size > 1000
    assert out["waypoints"][0] == [2.0, 3.0, 0.0] and out["waypoints"][-1] == [9.5, 9.5, 0.0]


def test_shipped_map_parses_with_four_goals():
    from controller.planning.route_maps import load_route_map

    m = load_route_map("yamashita")
    assert [n for n, _ in m.goals] == ["Goal1", "Goal2", "Goal3", "Goal4"]
    assert np.allclose(m.bounds, [[0, 0], [12.8, 12.8]])
    cs = build_object_cspace(m.bounds, list(m.obstacles), m.footprint, m.robot_radius, 0.1, 36)
    assert cs.occupied.shape == (36, 128, 128)
    s = cs.cell_of(m.start)
    assert all(cs.labels[cs.cell_of(g)] == cs.labels[s] for _, g in m.goals)
