"""The transport mission on its own, outside the job: a scenario's config, the robots it
places on the crate, a fleet view at a time, and the contact-force LP's feasibility check
(shared by tests/unit/test_transport_mission.py, test_planners.py, test_heavy_loads.py)."""

from __future__ import annotations

import numpy as np

from controller.mission.grip import CONTACT_REACH, touching
from controller.mission.guard import SafetyStage
from controller.mission.job import CaptureJob
from controller.mission.transport import TransportMission
from controller.mission.types import FleetView, Phase
from controller.planning.contact_lp import ContactForceLP, required_wrench
from tests.support.transport_scenarios import Scenario, scenario_config


def view(cfg, t, poses, obj, present=None):
    """The fleet as the mission sees it at ``t``: robots at ``poses`` (all present unless
    ``present`` says), standing, the object at ``obj`` at rest."""
    n = len(cfg.robots)
    return FleetView(
        t, cfg.robot_ids, np.asarray(poses, float), np.zeros((n, 3)), np.zeros(n, bool),
        np.ones(n, bool) if present is None else np.asarray(present, bool),
        np.asarray(obj, float), np.zeros(3), None, False,
    )  # fmt: skip


def holders(cfg):
    """The robots the scenario places on the crate: indices, contact points, outward normals
    (the job's own measure of who touches the object at the carry, ``grip.touching``)."""
    poses = np.array([r.start for r in cfg.robots])
    return touching(cfg, cfg.object.start, poses, CONTACT_REACH)


def mission(sc: Scenario, seed: int = 0) -> tuple[TransportMission, object, np.ndarray]:
    cfg = scenario_config(sc)
    held, pts, nrm = holders(cfg)
    m = TransportMission(cfg, np.random.default_rng(seed), SafetyStage(cfg), held, pts, nrm)
    return m, cfg, np.array([r.start for r in cfg.robots])


def carry_job(sc: Scenario, seed: int = 0) -> tuple[CaptureJob, object, np.ndarray]:
    """The same transport as the whole job runs it (``fleet run --mission transport``): the
    job entered at route, its roster and outage watch (lost robots, outages) in front of it."""
    cfg = scenario_config(sc)
    job = CaptureJob(cfg, np.random.default_rng(seed), entry=Phase.ROUTE)
    return job, cfg, np.array([r.start for r in cfg.robots])


def lp_feasible(m, pts, nrm, twist, fmax):
    """Whether the contact-force LP finds forces at these contacts for ``twist`` (each
    robot pushing at most ``fmax`` N)."""
    w = required_wrench(twist, m.model.mass, m.model.floor_friction, m.model.mean_radius)
    lp = ContactForceLP(len(pts))
    res = lp.solve(
        pts - m.model.centroid, -nrm, np.full(len(pts), fmax), np.ones(len(pts), bool), w,
        0.0, m.model.mean_radius,
    )  # fmt: skip
    return res.status == "optimal"
