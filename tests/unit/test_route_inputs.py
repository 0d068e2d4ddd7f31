"""Route inputs: maps, configs and the command line; every mistake exits 2 naming file and key."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from controller.cli import main
from controller.config import ConfigError, RouteSection, parse_config
from controller.planning.cspace import CSpaceError
from controller.planning.route import RoutePlanner, plan_route
from tests.support.config import base_config_dict, deep_update, write_toml

SQUARE = np.array([[-0.2, -0.1], [0.2, -0.1], [0.2, 0.1], [-0.2, 0.1]])

MAP_TOML = """
[map]
name = "tiny"
robot_radius = {radius}
[world]
bounds = {bounds}
[object]
polygon = [[-0.2, -0.1], [0.2, -0.1], [0.2, 0.1], [-0.2, 0.1]]
start = [0.8, 0.8, 0.0]
[[goals]]
name = "open"
pose = {goal}
[[goals]]
name = "boxed"
pose = [3.0, 3.0, 0.0]
{boxes}
"""

BOXES = [(2.3, 2.3, 3.7, 2.4), (2.3, 3.6, 3.7, 3.7), (2.3, 2.3, 2.4, 3.7), (3.6, 2.3, 3.7, 3.7)]


def _rect(x0, y0, x1, y1) -> list[list[float]]:
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def map_file(tmp_path, **over) -> str:
    fields = {
        "radius": "0.05",
        "bounds": "[[0.0, 0.0], [4.0, 4.0]]",
        "goal": "[3.2, 0.8, 0.0]",
        "boxes": "".join(f"[[obstacles]]\npolygon = {_rect(*r)}\n" for r in BOXES),
    }
    fields.update(over)
    text = MAP_TOML
    for k, v in fields.items():
        text = text.replace("{" + k + "}", v)
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return str(path)


# --------------------------------------------------------------------------- route maps


BAD_MAPS = {
    "reversed_bounds": ({"bounds": "[[4.0, 4.0], [0.0, 0.0]]"}, "world.bounds", "max > min"),
    "negative_radius": ({"radius": "-0.1"}, "map.robot_radius", ">= 0"),
    "two_vertex_obstacle": (
        {"boxes": "[[obstacles]]\npolygon = [[1.0, 1.0], [2.0, 1.0]]\n"},
        "obstacles[0].polygon",
        "at least 3 vertices",
    ),
    "two_number_goal": ({"goal": "[3.2, 0.8]"}, "goals[0].pose", "3 items"),
    "unknown_key": ({"radius": "0.05\nrobot_radios = 1"}, "map.robot_radios", "did you mean"),
    "not_a_number": ({"radius": '"wide"'}, "map.robot_radius", "a number"),
}


@pytest.mark.parametrize("case", sorted(BAD_MAPS))
def test_a_bad_route_map_exits_2_naming_file_and_key(case, tmp_path, capsys):
    over, key, words = BAD_MAPS[case]
    f = map_file(tmp_path, **over)
    assert main(["plan", "route", "--map", f, "--goal", "1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f in err and key in err and words in err, err


def test_missing_files_and_goals_exit_2(tmp_path, capsys):
    assert main(["plan", "route", "--map", str(tmp_path / "nope.toml")]) == 2
    assert "cannot read" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[map\n")
    assert main(["plan", "route", "--map", str(bad)]) == 2
    assert "not valid TOML" in capsys.readouterr().err
    f = map_file(tmp_path)
    assert main(["plan", "route", "--map", f, "--goal", "7"]) == 2
    err = capsys.readouterr().err
    assert "goals" in err and "open, boxed" in err


@pytest.mark.parametrize(
    "args, words",
    [
        (["--wh", "inf"], "--wh: expected a finite number"),
        (["--wh", "-1"], "--wh: expected a value >= 0"),
        (["--wh", "1000"], "--wh: expected a value <= 100"),
    ],
)
def test_bad_command_line_values_exit_2_naming_the_flag(args, words, tmp_path, capsys):
    f = map_file(tmp_path)
    assert main(["plan", "route", "--map", f, "--goal", "1", *args]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    with pytest.raises(SystemExit) as exc:
        main(["plan", "route", "--map", f, "--wg", "0.5"])
    assert exc.value.code == 2


def test_bad_planner_inputs_raise_config_errors_naming_the_parameter():
    bounds = np.array([[0.0, 0.0], [4.0, 4.0]])
    p = RouteSection()
    cases = [
        (dict(bounds=[[4.0, 4.0], [0.0, 0.0]]), "bounds"),
        (dict(robot_radius=-0.1), "robot_radius"),
        (dict(obstacles=[[[1.0, 1.0], [2.0, 1.0]]]), "obstacles[0]"),
        (dict(footprint_polygon=[[0, 0], [1, 1]]), "footprint"),
    ]
    for over, key in cases:
        kw = dict(
            bounds=bounds,
            obstacles=[],
            footprint_polygon=SQUARE,
            robot_radius=0.05,
            start=(1, 1, 0),
            goal=(3, 3, 0),
            params=p,
        )
        kw.update(over)
        with pytest.raises(CSpaceError) as exc:
            plan_route(**kw)
        assert isinstance(exc.value, ConfigError) and exc.value.path == key
    with pytest.raises(ValueError, match="goal"):
        plan_route(bounds, [], SQUARE, 0.05, (1, 1, 0), (3, 3), p)


# --------------------------------------------------------------------------- fleet.toml


def _config(patch: dict, drop=None):
    data = deep_update(base_config_dict(), patch)
    if drop:
        drop(data)
    return data


@pytest.mark.parametrize("key", ["start", "goal"])
def test_object_start_or_goal_inside_an_obstacle_is_a_config_error(key, tmp_path, capsys):
    data = base_config_dict()
    bench = data["obstacles"][0]["polygon"]  # the bench in the middle of the room
    x, y = bench[0]
    data["object"][key] = [x + 0.2, y + 0.2, 0.0]
    with pytest.raises(ConfigError) as exc:
        parse_config(data, "t.toml")
    assert exc.value.path == f"object.{key}" and "obstacles[0]" in exc.value.message
    path = write_toml(tmp_path / "bad.toml", data)
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"object.{key}" in err and "obstacles[0]" in err


def test_the_route_grids_have_a_budget_named_by_their_keys():
    with pytest.raises(ConfigError) as exc:
        parse_config(_config({"route": {"resolution": 0.0125}}), "t.toml")
    assert exc.value.path == "route.resolution"
    assert "route.heading_bins" in exc.value.message and "budget" in exc.value.message
    with pytest.raises(ConfigError) as exc:
        parse_config(_config({"route": {"resolution": 0.05, "heading_bins": 360}}), "t.toml")
    assert exc.value.path == "route.resolution" and "360" in exc.value.message
    with pytest.raises(ConfigError) as exc:
        parse_config(_config({"route": {"robot_resolution": 0.01}}), "t.toml")
    assert exc.value.path == "route.robot_resolution"
    # 512 x 512 x 36 over the shipped room is within the budget
    cfg = parse_config(_config({"route": {"resolution": 0.025}}), "t.toml")
    assert cfg.route.resolution == 0.025 and cfg.route.heuristic == "cost_to_go"


def test_a_map_beyond_the_grid_budget_exits_2(tmp_path, capsys):
    f = map_file(tmp_path, bounds="[[0.0, 0.0], [400.0, 400.0]]")
    assert main(["plan", "route", "--map", f, "--goal", "1"]) == 2
    assert "route.resolution" in capsys.readouterr().err


# --------------------------------------------------------------------------- the command


KEYS = {"status", "reason", "waypoints", "subgoals", "cost", "length_m", "manipulations"}
KEYS |= {"expanded", "reexpanded", "seconds", "heuristic", "wg", "wh"}


def test_cli_json_fields_and_exit_codes(tmp_path, capsys):
    f = map_file(tmp_path)
    rc = main(["plan", "route", "--map", f, "--goal", "1", "--heuristic", "wavefront", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and set(out) == KEYS
    assert out["status"] == "ok" and out["heuristic"] == "wavefront" and out["wg"] == 1.0
    assert len(out["waypoints"][0]) == 3 and out["cost"] > 0 and out["expanded"] > 0
    assert out["waypoints"][0] == [0.8, 0.8, 0.0] and out["waypoints"][-1] == [3.2, 0.8, 0.0]
    rc = main(["plan", "route", "--map", f, "--goal", "boxed", "--wh", "0.5", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 1 and out["status"] == "no_path" and out["cost"] is None and out["wh"] == 0.5
    assert "unreachable" in out["reason"]


def test_cli_plans_the_fleet_config_and_plots(tmp_path, capsys):
    png = tmp_path / "route.png"
    rc = main(["plan", "route", "--config", "fleet.toml", "--json", "--plot", str(png)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["status"] == "ok" and png.stat().st_size > 1000
    assert out["heuristic"] == "cost_to_go"
    assert out["waypoints"][0] == [2.0, 3.0, 0.0] and out["waypoints"][-1] == [9.5, 9.5, 0.0]


def test_planner_rejects_a_cspace_of_other_parameters():
    from controller.planning.cspace import build_object_cspace

    cs = build_object_cspace([[0, 0], [4, 4]], [], SQUARE, 0.05, 0.1, 12)
    with pytest.raises(ValueError, match="heading"):
        RoutePlanner(cs, (3, 3, 0), RouteSection(heading_bins=8))


def test_a_planner_from_the_fleet_config_plans_the_shipped_scenario():
    from controller.config import load_config
    from controller.planning.route import object_cspace

    cfg = load_config("fleet.toml")
    cs = object_cspace(cfg)
    planner = RoutePlanner.from_config(cfg, cspace=cs)
    res = planner.plan(cfg.object.start)
    assert res.ok and np.allclose(res.waypoints[-1], cfg.object.goal)
    assert np.allclose(res.subgoals[-1], cfg.object.goal) and res.manipulations >= 1
    # a second goal on the same C-space
    other = RoutePlanner.from_config(cfg, goal=(2.0, 9.0, 1.5707963), cspace=cs).plan(
        cfg.object.start
    )
    assert other.ok and other.cost > 0


def test_an_object_arrested_against_an_obstacle_slides_clear_before_its_route():
    """An object stopped touching a pillar (an arrest that ended there) leaves the robots no room
    around it: the route first slides it clear by one straight move at its heading, never into
    an obstacle, with room for a pusher behind it; one that overlaps an obstacle has none."""
    from controller.config import load_config
    from controller.planning.route import build_object_cspace
    from tests.support.config import FLEET_TOML

    cfg = load_config(FLEET_TOML)
    obs = [np.asarray(o.polygon) for o in cfg.obstacles]
    foot = np.asarray(cfg.object.polygon)
    radius = max(r.radius for r in cfg.robots)
    cs = build_object_cspace(
        cfg.world.bounds, obs, foot, radius, cfg.route.resolution, cfg.route.heading_bins
    )
    start = np.array([8.0, 2.5, 0.0])  # the L's right edge on the pillar's face (x = 9.0)
    assert not cs.is_free(start) and cs.clearance(start)[0] == 0.0 and cs.overlap(start) == 0.0
    res = plan_route(None, [], foot, radius, start, cfg.object.goal, cfg.route, cspace=cs)
    assert res.status == "ok", res.reason
    wp = res.waypoints
    assert np.allclose(wp[0], start) and np.allclose(wp[-1], cfg.object.goal)
    escape = wp[1]
    assert escape[2] == start[2] and cs.is_free(escape)  # a straight move, free at its end
    assert 0 < np.hypot(*(escape[:2] - start[:2])) <= 4 * 2 * radius + 1e-9
    for f in np.linspace(0.0, 1.0, 41):  # the object never enters an obstacle on the way
        assert cs.overlap(start + f * (escape - start)) < 1e-6
    u = (escape - start) / np.hypot(*(escape[:2] - start[:2]))
    assert cs.pusher_room(start, u[:2], math.radians(60))  # a pusher fits behind it
    assert np.allclose(res.subgoals[0], escape) and res.manipulations >= 1
    # planned from the escape pose, the rest is the route of an object that starts there
    alone = plan_route(None, [], foot, radius, escape, cfg.object.goal, cfg.route, cspace=cs)
    assert np.allclose(res.waypoints[1:], alone.waypoints)
    assert res.cost == pytest.approx(
        alone.cost
        + np.hypot(*(escape[:2] - start[:2])) / cfg.route.speed
        + cfg.route.manipulation_cost
    )
    # turned a little on the pillar's face (a real-time rehearsal's arrest): the object moved
    # back whole would graze the pillar, yet a robot fits on the faces that push it clear
    tilted = np.array([7.997, 2.92, -0.008])
    assert cs.clearance(tilted)[0] < 0.002 and cs.overlap(tilted) < 1e-6
    res = plan_route(None, [], foot, radius, tilted, cfg.object.goal, cfg.route, cspace=cs)
    assert res.status == "ok", res.reason
    u = (res.waypoints[1] - tilted)[:2] / np.hypot(*(res.waypoints[1] - tilted)[:2])
    assert cs.pusher_room(tilted, u, math.radians(60))
    # an object overlapping the pillar is not moved out of it: no route, the reason named
    inside = np.array([8.2, 2.5, 0.0])
    assert cs.overlap(inside) > 0.01
    res = plan_route(None, [], foot, radius, inside, cfg.object.goal, cfg.route, cspace=cs)
    assert res.status == "no_path" and "start pose collides" in res.reason


def test_a_pusher_fits_only_where_a_robot_can_stand():
    """Room to push an object one way: a robot's disc against a face it can push from, clear of
    obstacles and walls (never from the side the object is flush against)."""
    from controller.planning.cspace import FootprintChecker

    block = np.array([[1.0, -1.0], [2.0, -1.0], [2.0, 1.0], [1.0, 1.0]])
    chk = FootprintChecker([[-3.0, -3.0], [3.0, 3.0]], [block], SQUARE, 0.2)
    flush = np.array([0.8, 0.0, 0.0])  # its east face on the block's west face
    cone = math.radians(60)
    assert chk.pusher_room(flush, [1.0, 0.0], 0.1, cone)  # from the west
    assert not chk.pusher_room(flush, [-1.0, 0.0], 0.1, cone)  # from the east: the block
    assert chk.pusher_room(flush, [0.0, 1.0], 0.1, cone)  # from the south, beside the block
    # in a corridor no wider than the object, nothing fits beside it
    narrow = FootprintChecker([[-3.0, -0.1], [3.0, 0.1]], [], SQUARE, 0.2)
    assert not narrow.pusher_room(np.zeros(3), [0.0, 1.0], 0.1, cone)
    assert narrow.pusher_room(np.zeros(3), [1.0, 0.0], 0.1, cone)  # behind it, along the way
