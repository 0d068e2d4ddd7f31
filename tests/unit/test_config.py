"""fleet.toml validation: the shipped config passes; each kind of mistake exits 2 with its path."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from controller import geometry
from controller.cli import main
from controller.config import ConfigError, load_config, parse_config
from tests.support.config import FLEET_TOML, ROOT, base_config_dict, deep_update, write_toml


def test_shipped_config_is_valid_and_realistic():
    cfg = load_config(FLEET_TOML)
    assert len(cfg.robots) == 6
    assert {r.kind for r in cfg.robots} == {"omni", "diff"}
    assert all(0.05 <= r.radius <= 0.2 for r in cfg.robots)
    poly = cfg.object_polygon()
    # concave (the hull is strictly larger) and about a metre across
    hull = geometry.convex_hull(poly)
    assert geometry.signed_area(hull) > geometry.signed_area(poly) * 1.2
    assert 0.7 <= np.ptp(poly[:, 0]) <= 1.5
    assert cfg.object.motion.kind == "sine"
    assert cfg.world.bounds == ((0.0, 0.0), (12.8, 12.8))
    assert len(cfg.obstacles) >= 2
    start, goal = np.array(cfg.object.start[:2]), np.array(cfg.object.goal[:2])
    assert np.linalg.norm(goal - start) > 6.0  # across the room


def test_fleet_check_cli_ok(capsys):
    assert main(["check", "--config", str(FLEET_TOML)]) == 0


def _bad(tmp_path, patch, drop=None):
    data = deep_update(base_config_dict(), patch)
    if drop:
        drop(data)
    return write_toml(tmp_path / "bad.toml", data)


CASES = {
    "unknown_key": ({"fleet": {"rate_hzz": 10}}, None, "fleet.rate_hzz", "did you mean 'rate_hz'"),
    "wrong_type": ({"fleet": {"rate_hz": "fast"}}, None, "fleet.rate_hz", "expected a number"),
    "negative_radius": (
        {},
        lambda d: d["robots"][2].update(radius=-0.1),
        "robots[2].radius",
        "> 0",
    ),
    "self_intersecting": (
        {"object": {"polygon": [[0, 0], [1, 1], [1, 0], [0, 1]]}},
        None,
        "object.polygon",
        "self-intersection",
    ),
    "duplicate_id": ({}, lambda d: d["robots"][3].update(id="r1"), "robots[3].id", "duplicate"),
    "robot_in_obstacle": (
        {},
        lambda d: d["robots"][1].update(start=[6.0, 5.4, 0.0]),
        "robots[1].start",
        "obstacles[0]",
    ),
    "robot_outside": (
        {},
        lambda d: d["robots"][0].update(start=[13.5, 1.0, 0.0]),
        "robots[0].start",
        "bounds",
    ),
    "unknown_kind": (
        {},
        lambda d: d["robots"][0].update(kind="legged"),
        "robots[0].kind",
        "'omni'",
    ),
    "unknown_driver": (
        {},
        lambda d: d["robots"][0].update(driver="ros"),
        "robots[0].driver",
        "'mavlink'",
    ),
    "two_vertices": (
        {"object": {"polygon": [[0, 0], [1, 0]]}},
        None,
        "object.polygon",
        "at least 3",
    ),
    "zero_area": ({"object": {"polygon": [[0, 0], [1, 0], [2, 0]]}}, None, "object.polygon", ""),
    "missing_section": ({}, lambda d: d.pop("object"), "object", "missing"),
    "unknown_capture_ga": ({"capture": {"ga": "matlab"}}, None, "capture.ga", "'paper'"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_config_exits_2_with_key_path(tmp_path, capsys, name):
    patch, drop, path, words = CASES[name]
    f = _bad(tmp_path, patch, drop)
    with pytest.raises(ConfigError) as err:
        load_config(f)
    assert err.value.path == path
    assert words in str(err.value)
    assert main(["check", "--config", str(f)]) == 2
    captured = capsys.readouterr()
    assert path in captured.err and str(f) in captured.err


def test_check_subprocess_exit_code(tmp_path):
    f = _bad(tmp_path, {"fleet": {"rate_hzz": 10}})
    proc = subprocess.run(
        [sys.executable, "-m", "controller.cli", "check", "--config", str(f)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "fleet.rate_hzz" in proc.stderr


def test_polygons_are_stored_counter_clockwise():
    data = base_config_dict()
    data["object"]["polygon"] = data["object"]["polygon"][::-1]  # clockwise in the file
    cfg = parse_config(data, "cw")
    assert geometry.signed_area(cfg.object_polygon()) > 0
    for o in cfg.obstacle_polygons():
        assert geometry.signed_area(o) > 0


def test_unknown_key_in_robot_table_names_index():
    data = base_config_dict()
    data["robots"][4]["max_sped"] = 1.0
    with pytest.raises(ConfigError) as err:
        parse_config(data, "x")
    assert err.value.path == "robots[4].max_sped"
    assert "max_speed" in str(err.value)


def test_check_json_reports_path(tmp_path, capsys):
    f = _bad(tmp_path, {"capture": {"closure": "magic"}})
    assert main(["check", "--config", str(f), "--json"]) == 2
    import json

    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and out["path"] == "capture.closure"


def test_expected_errors_map_to_exit_codes_in_one_place():
    from controller.cli import EXIT_BAD_INPUT, EXIT_FAILED, exit_code
    from controller.config import ConfigError, InputError
    from controller.io.bus import BusError
    from controller.mission.job import MissionError

    assert exit_code(ConfigError("f.toml", "fleet.rate_hz", "bad")) == EXIT_BAD_INPUT == 2
    assert exit_code(InputError("no such file")) == EXIT_BAD_INPUT
    assert exit_code(MissionError("too few robots")) == EXIT_FAILED == 1
    assert exit_code(BusError("nobody answered")) == EXIT_FAILED
    assert exit_code(ZeroDivisionError()) is None  # a bug keeps its traceback
