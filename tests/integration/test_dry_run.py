"""The lockstep dry run end to end over zenoh: determinism, logging, the verdict."""

from __future__ import annotations

import json

import numpy as np

from controller.io.recorder import read_log
from controller.mission.basic import GotoMission
from controller.mission.tracking import RobotLimits
from controller.runtime.dry_run import DryRun, judge
from tests.support.config import make_config


def truth_track(path):
    out = []
    for rec in read_log(path):
        if "/sim/truth/" in rec.topic:
            m = rec.decoded()
            out.append((rec.topic, m["t"], m["x"], m["y"], m["theta"]))
    return out


def run_goto(cfg, path, max_time=4.0):
    targets = np.array(cfg.robots[0].start[:2]) + np.array(
        [[1.0 + 0.5 * i, 1.0] for i in range(len(cfg.robots))]
    )
    mission = GotoMission(targets, RobotLimits.from_config(cfg.robots))
    return DryRun(cfg, mission, path, max_time=max_time).run()


def test_same_seed_same_truth(tmp_path):
    patch = {"sim": {"backend": "ideal", "seed": 3}}
    a = run_goto(make_config(patch), tmp_path / "a.mcap")
    b = run_goto(make_config(patch), tmp_path / "b.mcap")
    ta, tb = truth_track(tmp_path / "a.mcap"), truth_track(tmp_path / "b.mcap")
    assert len(ta) > 100
    assert sorted(ta) == sorted(tb)
    assert a["missed_ticks"] == 0 and b["missed_ticks"] == 0


def test_every_command_crosses_the_bus_and_is_logged(tmp_path):
    cfg = make_config({"sim": {"backend": "ideal"}})
    res = run_goto(cfg, tmp_path / "c.mcap", max_time=2.0)
    recs = list(read_log(tmp_path / "c.mcap"))
    cmds = [r for r in recs if r.topic.endswith("/cmd")]
    poses = [r for r in recs if r.topic.endswith("/pose") and "/robot/" in r.topic]
    assert len(cmds) == res["ticks"] * len(cfg.robots)
    assert len(poses) >= res["ticks"]  # 30 Hz sensors, 20 Hz ticks
    assert {r.schema for r in cmds} == {"fleet.Twist2D"}
    assert res["node"]["commands"] == len(cmds)
    assert res["bad_payloads"] == 0
    json.dumps(res)  # the summary is JSON-ready


def mavlink_patch(port_a: int, port_b: int) -> dict:
    return {
        "sim": {"backend": "ideal"},
        "robots": [
            {**r, **extra}
            for r, extra in zip(
                base_robots(),
                [
                    {
                        "driver": "mavlink",
                        "profile": "px4",
                        "url": f"udpin:127.0.0.1:{port_a}",
                        "system_id": 1,
                    },
                    {},
                    {
                        "driver": "mavlink",
                        "profile": "ardurover",
                        "url": f"udpin:127.0.0.1:{port_b}",
                        "system_id": 3,
                    },
                    {},
                    {},
                    {},
                ],
                strict=True,
            )
        ],
    }


def base_robots() -> list[dict]:
    from tests.support.config import base_config_dict

    return base_config_dict()["robots"]


def test_mavlink_robots_run_the_same_job(tmp_path):
    from tests.support.mavlink_rig import free_udp_port

    cfg = make_config(mavlink_patch(free_udp_port(), free_udp_port()))
    assert [r.driver for r in cfg.robots][:3] == ["mavlink", "sim", "mavlink"]
    res = run_goto(cfg, tmp_path / "m.mcap", max_time=25.0)
    assert res["done"], res
    assert res["missed_ticks"] == 0
    recs = list(read_log(tmp_path / "m.mcap"))
    mav_poses = [r for r in recs if r.topic == "fleet/lab/robot/r1/pose"]
    assert len(mav_poses) > 100  # the MAVLink robot's poses crossed the bus


def test_default_scenario_with_mavlink_robots_arrests_the_object(tmp_path):
    """fleet.toml with r1 (PX4, omni) and r3 (ArduRover, diff) behind the MAVLink driver and
    emulated vehicles: the capture job arrests the object as it does with sim drivers."""
    from controller.mission.factory import build_mission
    from tests.support.mavlink_rig import free_udp_port

    cfg = make_config(mavlink_patch(free_udp_port(), free_udp_port()))
    res = DryRun(cfg, build_mission(cfg), tmp_path / "cap.mcap", max_time=90.0).run()
    assert res["arrested"] and res["done"] and not res["failed"], res
    assert res["min_clearance_m"] is not None and judge(res) == []
    assert res["missed_ticks"] == 0
