"""Mission factory: which mission a config runs (pure construction, no I/O)."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import MISSION_KINDS, FleetConfig
from controller.mission.basic import GotoMission, HoldMission
from controller.mission.job import CaptureJob, MissionError
from controller.mission.planners import Planners
from controller.mission.tracking import RobotLimits
from controller.mission.types import Phase


def staging_targets(cfg: FleetConfig, margin: float = 0.6) -> np.ndarray:
    """Fixed targets on a ring around the object's start (staging before capture)."""
    poly = geometry.transform(cfg.object_polygon(), cfg.object.start)
    c = geometry.centroid(poly)
    r = float(np.max(np.linalg.norm(poly - c, axis=1))) + margin
    n = len(cfg.robots)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False) + np.pi / n
    return c + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)


def build_mission(
    cfg: FleetConfig,
    kind: str = "capture",
    capture: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    rng: np.random.Generator | None = None,
    planners: Planners | None = None,
):
    """The mission a config runs: ``capture`` (the whole job: GA plan, assignment, approach,
    arrest), ``stage`` (drive to a ring of staging points around the object) or ``hold``
    (everyone stopped).

    ``capture`` = (points (M, 2), outward normals (M, 2), both in the object frame, robot index
    per point (M,)) replaces the GA plan and the assignment (hand-made capture sets). ``rng``
    defaults to one seeded from ``capture.seed``; ``planners``: the port the slow plans are
    asked of off the tick (None: computed at once, the same tick)."""
    if kind not in MISSION_KINDS:
        raise MissionError(f"unknown mission {kind!r}; expected one of {MISSION_KINDS}")
    if kind == "hold":
        return HoldMission(len(cfg.robots))
    if kind == "transport":  # the same job, entered at route (the object already held)
        gen = rng if rng is not None else np.random.default_rng(cfg.transport.seed)
        return CaptureJob(cfg, gen, planners, entry=Phase.ROUTE)
    if kind == "stage":
        return GotoMission(staging_targets(cfg), RobotLimits.from_config(cfg.robots))
    gen = rng if rng is not None else np.random.default_rng(cfg.capture.seed)
    if capture is not None:
        from controller.mission.capture import CaptureMission

        points, normals, assignment = capture
        return CaptureMission(points, normals, assignment, cfg, gen)
    return CaptureJob(cfg, gen, planners)
