"""The grip's relocations: a robot near its new contact goes straight in; one across the object
goes round it by the lane."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import load_config
from controller.mission.grip import Contact, Grip, GripSettings
from controller.planning.transport_model import ObjectModel
from tests.support.config import ROOT
from tests.support.transport_mission import view


def _grip(cfg) -> Grip:
    o = cfg.object
    model = ObjectModel.build(
        cfg.object_polygon(), o.mass, o.floor_friction, o.contact_friction, cfg.max_robot_radius
    )
    return Grip(cfg, model, GripSettings(), np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 2)))


def test_a_robot_beside_its_contact_goes_straight_in_not_by_the_lane_into_a_bench():
    """The README lab's stall: the crate stopped beside the bench, r4 squeezed between them
    and sent to the contact on the crate's bench side. The lane's point lies inside the
    bench's safety margin; r4 goes straight to its station instead, away from the bench."""
    cfg = load_config(str(ROOT / "lab.toml"))
    g = _grip(cfg)
    obj = np.array([4.22, 5.55, 0.18])
    poses = np.array([r.start for r in cfg.robots], float)
    r4 = cfg.robot_ids.index("r4")
    poses[r4] = [5.449, 5.654, 1.768]
    v = view(cfg, 0.0, poses, obj)
    g.relocate(r4, Contact(np.array([1.0, 0.05]), np.array([-1.0, 0.0])), v, obj)
    vel, touch = np.zeros((len(cfg.robots), 2)), np.zeros(len(cfg.robots), bool)
    g.follow_paths(v, obj, vel, touch)
    station = geometry.transform(np.array([[1.0 + cfg.robots[r4].radius, 0.05]]), obj)[0]
    to_station = (station - poses[r4, :2]) / np.linalg.norm(station - poses[r4, :2])
    assert vel[r4] @ to_station / np.linalg.norm(vel[r4]) > 0.999  # straight at it
    assert vel[r4, 0] < 0  # away from the bench (x = 5.6), not into its margin
    assert len(g.moves[r4]) <= 2  # the lane dropped: the station is next


def test_a_robot_across_the_object_still_goes_round_by_the_lane():
    cfg = load_config(str(ROOT / "lab.toml"))
    g = _grip(cfg)
    obj = np.array([3.0, 3.0, 0.0])
    poses = np.array([r.start for r in cfg.robots], float)
    poses[0] = [3.0 - 0.3, 3.3, 0.0]  # west of the L, its contact on the east side
    v = view(cfg, 0.0, poses, obj)
    g.relocate(0, Contact(np.array([1.0, 0.05]), np.array([-1.0, 0.0])), v, obj)
    vel, touch = np.zeros((len(cfg.robots), 2)), np.zeros(len(cfg.robots), bool)
    g.follow_paths(v, obj, vel, touch)
    assert len(g.moves[0]) > 2  # round the object, by the lane
