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


def _ardurover(**mavlink) -> dict:
    """Flat keys of an ArduRover robot (robots[2] of fleet.toml is differential)."""
    return {"driver": "mavlink", "profile": "ardurover", "url": "udpin:127.0.0.1:14551", **mavlink}


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
        "expected one of 'sim', 'mavlink', 'ros2', got 'ros'",
    ),
    "subtable_and_flat_differ": (
        {},
        lambda d: d["robots"][0].update(
            driver="mavlink", url="udpin:127.0.0.1:14551", mavlink={"url": "udpin:127.0.0.1:9"}
        ),
        "robots[0].mavlink.url",
        "given as robots[0].url = 'udpin:127.0.0.1:14551' and robots[0].mavlink.url",
    ),
    "subtable_unknown_key": (
        {},
        lambda d: d["robots"][0].update(driver="mavlink", mavlink={"heartbeat": 2.0}),
        "robots[0].mavlink.heartbeat",
        "did you mean 'heartbeat_hz'",
    ),
    "heartbeat_hz_zero": (
        {},
        lambda d: d["robots"][0].update(driver="mavlink", mavlink={"heartbeat_hz": 0.0}),
        "robots[0].mavlink.heartbeat_hz",
        ">= 0.2",
    ),
    "subtable_of_another_driver": (
        {},
        lambda d: d["robots"][1].update(mavlink={"url": "udpin:127.0.0.1:14551"}),
        "robots[1].mavlink",
        "driver = 'sim': set driver = \"mavlink\"",
    ),
    "fs_timeout_flaps_against_the_heartbeat": (
        {},
        lambda d: d["robots"][2].update(**_ardurover(), mavlink={"fs_timeout": 1.0}),
        "robots[2].mavlink.fs_timeout",
        "set FS_TIMEOUT >= 3 s",
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


# --------------------------------------------------------------------------- driver sub-tables


def _robots(*updates: dict) -> tuple:
    data = base_config_dict()
    for r, u in zip(data["robots"], updates, strict=False):
        r.update(u)
    return parse_config(data, "t.toml").robots


def test_mavlink_subtable_equals_the_flat_keys():
    flat = {**_ardurover(), "system_id": 7, "link_timeout": 3.0, "hold_on_close": False}
    sub = {
        "driver": "mavlink",
        "mavlink": {k: v for k, v in flat.items() if k != "driver"},
    }
    a = _robots({}, {}, flat)[2]
    b = _robots({}, {}, sub)[2]
    assert a == b
    # the flat attributes stay readable (drivers, wiring and tools read robot.url etc.)
    assert (b.url, b.system_id, b.profile, b.link_timeout, b.hold_on_close) == (
        "udpin:127.0.0.1:14551",
        7,
        "ardurover",
        3.0,
        False,
    )
    assert b.mavlink.heartbeat_hz == 1.0  # today's rate by default


def test_flat_and_subtable_may_agree():
    r = _robots({}, {}, {**_ardurover(), "mavlink": {"url": "udpin:127.0.0.1:14551"}})[2]
    assert r.url == "udpin:127.0.0.1:14551"


def test_subtable_checks_run_as_for_the_flat_keys():
    with pytest.raises(ConfigError) as err:
        _robots({}, {}, {"driver": "mavlink", "mavlink": {"profile": "ardurover"}})
    assert err.value.path == "robots[2].url" and "needs a url" in str(err.value)


def test_ardurover_without_fs_timeout_gets_the_failsafe_advice(capsys):
    data = base_config_dict()
    data["robots"][2].update(**_ardurover(), mavlink={"heartbeat_hz": 2.0})
    cfg = parse_config(data, "t.toml")
    assert any("FS_TIMEOUT >= 1.5 s" in n and "robots[2]" in n for n in cfg.notes), cfg.notes
    data["robots"][2]["mavlink"]["fs_timeout"] = 1.5  # three periods at 2 Hz: accepted
    assert not any("FS_TIMEOUT" in n for n in parse_config(data, "t.toml").notes)


def test_config_dict_keeps_flat_keys_and_loads_again(tmp_path):
    from controller.config import config_to_dict

    data = base_config_dict()
    data["robots"][2].update(**_ardurover(), mavlink={"heartbeat_hz": 2.0, "fs_timeout": 2.0})
    cfg = parse_config(data, "t.toml")
    d = config_to_dict(cfg)
    assert d["robots"][2]["url"] == d["robots"][2]["mavlink"]["url"] == "udpin:127.0.0.1:14551"
    assert d["robots"][2]["mavlink"]["heartbeat_hz"] == 2.0
    assert "mavlink" not in d["robots"][0] and d["robots"][0]["url"] == ""  # a sim robot
    d.pop("source")  # the loader's record of the file, not a key
    again = load_config(write_toml(tmp_path / "again.toml", d))
    assert again.robots == cfg.robots


def test_every_config_driver_has_a_class_and_back():
    """The two registries name the same drivers: config sections (controller.config) and
    classes (controller.runtime.wiring, the only importer of drivers/)."""
    from controller.config import DRIVER_SPECS, DRIVERS
    from controller.runtime.wiring import DRIVER_CLASSES

    assert set(DRIVER_SPECS) == set(DRIVER_CLASSES) == set(DRIVERS) >= {"sim", "mavlink"}


def test_a_driver_class_needs_a_config_entry():
    from controller.runtime.wiring import DriverClass, register_driver_class

    with pytest.raises(ValueError, match="no config entry"):
        register_driver_class(DriverClass("canbus", lambda *a: None, lambda *a: (None, None)))


# --------------------------------------------------------------------------- transport strategies


def test_transport_strategy_names_are_one_registry():
    """transport.strategy names (config) and their local planners (planning) are the same set;
    an unknown name fails at load with the valid ones."""
    from controller.config import TRANSPORT_STRATEGIES
    from controller.planning.transport import LOCAL_PLANNERS
    from controller.planning.transport_types import STRATEGIES

    assert set(LOCAL_PLANNERS) == set(TRANSPORT_STRATEGIES) == set(STRATEGIES)
    data = deep_update(base_config_dict(), {"transport": {"strategy": "greedy"}})
    with pytest.raises(ConfigError) as err:
        parse_config(data, "t.toml")
    assert err.value.path == "transport.strategy"
    assert "expected one of 'sa', 'serpentine', 'downhill', got 'greedy'" in str(err.value)


def test_no_call_site_compares_a_strategy_name():
    """The annealer's warm start, the mission's followers and the arrangement ask the strategy
    object (``planning.transport.LOCAL_STRATEGIES``), never its name (issue 35 item 4): no
    comparison of anything named ``strategy`` with a string outside the config."""
    import ast

    from tests.support.config import ROOT

    found = []
    for path in sorted((ROOT / "controller").rglob("*.py")):
        if "config" in path.parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if not isinstance(node, ast.Compare):
                continue
            sides = [node.left, *node.comparators]
            named = any("strategy" in ast.unparse(x) for x in sides)
            if named and any(
                isinstance(x, ast.Constant) and isinstance(x.value, str) for x in sides
            ):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    assert found == []


@pytest.mark.parametrize("strategy", ["sa", "downhill", "serpentine"])
def test_each_strategy_plans_through_the_registry(strategy):
    from controller.planning.transport import plan_local
    from controller.planning.transport_types import TransportParams
    from tests.support.transport_cases import push_case

    params = TransportParams(strategy=strategy, iterations=20)
    plan = plan_local(push_case(), params, np.random.default_rng(0))
    assert plan.strategy == strategy and plan.status == "ok"
    assert plan.energy.total <= plan.start_energy.total + 1e-9  # never worse than its start
