"""``[robots.ros2]``: the keys a ROS 2 robot's entry takes, and ``fleet check`` refusing bad
values with exit 2 and the key path."""

from __future__ import annotations

import pytest

from controller.cli import main
from controller.config import ConfigError, load_config
from controller.runtime.wiring import DRIVER_CLASSES, ros2_settings
from drivers.ros2.driver import Ros2Driver, Ros2Settings
from tests.support.config import base_config_dict, deep_update, write_toml


def _config(tmp_path, ros2=None, robot=0, **flat):
    data = deep_update(base_config_dict(), {})
    r = data["robots"][robot]
    r.update(driver="ros2", **flat)
    if ros2 is not None:
        r["ros2"] = ros2
    return write_toml(tmp_path / "fleet.toml", data)


def test_a_ros2_robot_loads_with_its_settings(tmp_path):
    f = _config(
        tmp_path,
        {
            "domain_id": 7,
            "namespace": "/tb4_1",
            "cmd_type": "twist_stamped",
            "pose_topic": "/mocap/tb4_1/pose",
            "pose_type": "pose_stamped",
            "odom_to_world": [1.5, 2.0, 1.5708],
            "connect": ["tcp/127.0.0.1:7447"],
        },
    )
    cfg = load_config(f)
    r = cfg.robots[0]
    s = ros2_settings(r)
    assert isinstance(s, Ros2Settings)
    assert (s.domain_id, s.namespace, s.cmd_type, s.pose_type) == (
        7, "/tb4_1", "twist_stamped", "pose_stamped",
    )  # fmt: skip
    assert s.odom_to_world == (1.5, 2.0, 1.5708)
    assert s.cmd_key().startswith("7/tb4_1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/")
    assert s.pose_key().startswith("7/mocap/tb4_1/pose/geometry_msgs::msg::dds_::PoseStamped_/")
    assert main(["check", "--config", str(f)]) == 0
    driver, world = DRIVER_CLASSES["ros2"].local(cfg, r, 0.0, False)
    assert isinstance(driver, Ros2Driver) and world is None
    assert driver.stale_after == cfg.fleet.stale_after
    driver.close()  # never opened: nothing to undeclare


def test_defaults_are_a_turtlebot_on_the_local_router(tmp_path):
    s = ros2_settings(load_config(_config(tmp_path)).robots[0])
    assert (s.cmd_topic, s.cmd_type, s.pose_topic, s.pose_type) == (
        "cmd_vel", "twist", "odom", "odometry",
    )  # fmt: skip
    assert s.connect == ("tcp/127.0.0.1:7447",) and s.domain_id == 0
    assert s.link_timeout == 2.5  # the MAVLink link's: a silence of stale_after is no loss


BAD = {
    "cmd_type": ({"cmd_type": "twist3d"}, "robots[0].ros2.cmd_type", "'twist_stamped'"),
    "pose_type": ({"pose_type": "tf"}, "robots[0].ros2.pose_type", "'odometry'"),
    "domain": ({"domain_id": 300}, "robots[0].ros2.domain_id", "<= 232"),
    "relative_namespace": ({"namespace": "tb1"}, "robots[0].ros2.namespace", "absolute"),
    "bad_topic": ({"cmd_topic": "cmd vel"}, "robots[0].ros2.cmd_topic", "not a ROS name"),
    "digit_topic": ({"pose_topic": "1odom"}, "robots[0].ros2.pose_topic", "not a ROS name"),
    "node_name": ({"node_name": "a/b"}, "robots[0].ros2.node_name", "node name"),
    "transform_size": ({"odom_to_world": [1.0, 2.0]}, "robots[0].ros2.odom_to_world", "3 items"),
    "transform_type": (
        {"odom_to_world": [1.0, 2.0, "north"]},
        "robots[0].ros2.odom_to_world[2]",
        "a number",
    ),
    "endpoint": ({"connect": ["localhost:7447"]}, "robots[0].ros2.connect[0]", "endpoint"),
    "no_endpoint": ({"connect": []}, "robots[0].ros2.connect", "at least one"),
    "same_topic": ({"pose_topic": "cmd_vel"}, "robots[0].ros2.pose_topic", "same topic"),
    "unknown_key": ({"cmd_topik": "x"}, "robots[0].ros2.cmd_topik", "did you mean 'cmd_topic'"),
    "time_source": ({"time_source": "gps"}, "robots[0].ros2.time_source", "'receipt'"),
    "link_timeout": ({"link_timeout": 0}, "robots[0].ros2.link_timeout", "> 0"),
    # the 33-byte attachment: jazzy >= 0.2.4, rolling >= 0.6.0, humble >= 0.1.2
    "old_jazzy": ({"rmw_zenoh": "jazzy 0.2.3"}, "robots[0].ros2.rmw_zenoh", "jazzy >= 0.2.4"),
    "old_rolling": ({"rmw_zenoh": "rolling 0.5.9"}, "robots[0].ros2.rmw_zenoh", "not supported"),
    "old_humble": ({"rmw_zenoh": "humble 0.1.1"}, "robots[0].ros2.rmw_zenoh", "humble >= 0.1.2"),
    "unknown_distro": ({"rmw_zenoh": "iron 1.0.0"}, "robots[0].ros2.rmw_zenoh", "unknown"),
    "version_form": ({"rmw_zenoh": "0.2.5"}, "robots[0].ros2.rmw_zenoh", "'jazzy 0.2.5'"),
}


@pytest.mark.parametrize("value", ["", "jazzy 0.2.4", "jazzy 0.2.10", "rolling 0.6.0",
                                   "humble 0.1.2", "humble 1.0.0"])  # fmt: skip
def test_supported_rmw_zenoh_releases_load(tmp_path, value):
    cfg = load_config(_config(tmp_path, {"rmw_zenoh": value}))
    assert ros2_settings(cfg.robots[0]).rmw_zenoh == value


@pytest.mark.parametrize("name", sorted(BAD))
def test_fleet_check_refuses_bad_ros2_values(tmp_path, capsys, name):
    table, path, words = BAD[name]
    f = _config(tmp_path, table)
    with pytest.raises(ConfigError) as err:
        load_config(f)
    assert err.value.path == path and words in str(err.value)
    assert main(["check", "--config", str(f)]) == 2
    assert path in capsys.readouterr().err


def test_two_robots_on_one_cmd_topic_are_refused(tmp_path, capsys):
    data = base_config_dict()
    for i in (0, 1):
        data["robots"][i].update(driver="ros2")
    f = write_toml(tmp_path / "fleet.toml", data)
    assert main(["check", "--config", str(f)]) == 2
    assert "robots[1].ros2.cmd_topic" in capsys.readouterr().err
    data["robots"][1]["ros2"] = {"namespace": "/tb2"}
    data["robots"][0]["ros2"] = {"namespace": "/tb1"}
    assert main(["check", "--config", str(write_toml(tmp_path / "ok.toml", data))]) == 0


def test_a_ros2_table_on_a_sim_robot_is_refused(tmp_path):
    data = base_config_dict()
    data["robots"][0]["ros2"] = {"namespace": "/tb1"}
    with pytest.raises(ConfigError) as err:
        load_config(write_toml(tmp_path / "fleet.toml", data))
    assert err.value.path == "robots[0].ros2" and 'driver = "ros2"' in str(err.value)


@pytest.mark.e2e
def test_a_dry_run_with_a_ros2_robot_is_refused_with_exit_2(tmp_path, capsys):
    data = base_config_dict()
    data["robots"][0].update(driver="ros2")
    data["sim"] = {**data.get("sim", {}), "backend": "ideal"}
    f = write_toml(tmp_path / "fleet.toml", data)
    assert main(["run", "--config", str(f), "--out", str(tmp_path / "run.mcap")]) == 2
    assert "a ros2 robot is a vehicle of its own" in capsys.readouterr().err


def test_the_ros2_table_survives_the_logs_config_record(tmp_path):
    """``fleet replay`` reloads the config from the log's metadata: the sub-table comes back."""
    import json

    from controller.config import parse_config
    from controller.io.recorder import config_metadata

    cfg = load_config(_config(tmp_path, {"namespace": "/tb1", "odom_to_world": [1, 2, 0.5]}))
    again = parse_config(json.loads(config_metadata(cfg, "daemon")["config"]), "log")
    assert again.robots[0].ros2 == cfg.robots[0].ros2
    assert again.robots[0].ros2.odom_to_world == (1.0, 2.0, 0.5)


def test_fleet_check_notes_an_odometry_left_at_the_origin(tmp_path, capsys):
    f = _config(tmp_path, {"namespace": "/tb1"})
    assert main(["check", "--config", str(f)]) == 0
    assert "ros2.odom_to_world" in capsys.readouterr().out
    start = base_config_dict()["robots"][0]["start"]
    f = _config(tmp_path, {"namespace": "/tb1", "odom_to_world": start})
    assert main(["check", "--config", str(f)]) == 0
    assert "odom_to_world" not in capsys.readouterr().out
