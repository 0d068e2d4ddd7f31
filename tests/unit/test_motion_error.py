"""Yamashita's robot motion errors in the stand-in world: each robot's pose reports are off by
a fixed offset within ``sim.robot_position_error`` (the object's are not)."""

from __future__ import annotations

import numpy as np

from sim_backend.sensors import make_sensors
from tests.support.transport_scenarios import CRATE, Scenario, scenario_config


def reports(patch: dict) -> tuple[np.ndarray, np.ndarray]:
    sc = Scenario("err", CRATE, (1.5, 2.5, 0.0), (4.5, 2.5, 0.0), patch=patch)
    cfg = scenario_config(sc)
    sensors = make_sensors(cfg)
    truth = np.array([1.0, 2.0, 0.0])
    rob = np.array([s.sample(0.0, truth)[0][1:3] for s in sensors.robots.values()]) - truth[:2]
    obj = np.array(sensors.object.sample(0.0, truth)[0][1:3]) - truth[:2]
    return rob, obj


def test_robot_reports_are_off_by_a_fixed_error_within_the_bounds():
    noiseless = {"pose_noise": {"xy": 0.0, "theta": 0.0}}
    rob, obj = reports({"sim": {**noiseless, "robot_position_error": [0.04, 0.01]}})
    assert np.all(np.abs(rob[:, 0]) <= 0.04) and np.all(np.abs(rob[:, 1]) <= 0.01)
    assert np.abs(rob[:, 0]).max() > 0.01  # the errors are there, along x up to 4 cm
    assert np.allclose(obj, 0.0)
    still, _ = reports({"sim": noiseless})
    assert np.allclose(still, 0.0)  # the default: no motion error
