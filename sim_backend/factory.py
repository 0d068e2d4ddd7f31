"""Choose the stand-in world by ``cfg.sim.backend``."""

from __future__ import annotations

from controller.config import FleetConfig
from sim_backend.base import World


def make_world(cfg: FleetConfig, gui: bool = False) -> World:
    """A world for ``cfg``: ``"pybullet"`` (physics; ``gui`` opens a window) or ``"ideal"``."""
    backend = cfg.sim.backend
    if backend == "pybullet":
        from sim_backend.pybullet_world import PybulletWorld

        return PybulletWorld(cfg, gui=gui)
    if backend == "ideal":
        from sim_backend.ideal import IdealWorld

        return IdealWorld(cfg)
    raise ValueError(f"sim.backend: unknown backend {backend!r} (expected 'pybullet' or 'ideal')")
