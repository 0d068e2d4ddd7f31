"""Mission factory: which mission a config runs (pure construction, no I/O)."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission import GotoMission, HoldMission, RobotLimits


def staging_targets(cfg: FleetConfig, margin: float = 0.6) -> np.ndarray:
    """Fixed targets on a ring around the object's start (staging before capture)."""
    poly = geometry.transform(cfg.object_polygon(), cfg.object.start)
    c = geometry.centroid(poly)
    r = float(np.max(np.linalg.norm(poly - c, axis=1))) + margin
    n = len(cfg.robots)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False) + np.pi / n
    return c + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)


def build_mission(cfg: FleetConfig, kind: str = "capture"):
    """The mission a config runs: ``capture`` (the whole job), ``stage`` (drive to a ring of
    staging points around the object) or ``hold`` (everyone stopped)."""
    if kind == "hold":
        return HoldMission(len(cfg.robots))
    return GotoMission(staging_targets(cfg), RobotLimits.from_config(cfg.robots))
