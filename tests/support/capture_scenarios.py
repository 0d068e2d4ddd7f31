"""The capture scenarios on GA plans (shapes, motions, fleets, obstacles): the table and its
config builder, shared by tests/scenarios/test_capture_scenarios.py and the robot-loss scenario."""

from __future__ import annotations

import numpy as np

from tests.support.config import base_config_dict, deep_update, free_port

RECT = [[0.0, 0.0], [0.9, 0.0], [0.9, 0.6], [0.0, 0.6]]
L_SHAPE = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]]
T_SHAPE = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.3], [0.65, 0.3], [0.65, 0.9], [0.35, 0.9],
           [0.35, 0.3], [0.0, 0.3]]  # fmt: skip
HEXAGON = [[0.5 + 0.45 * np.cos(a), 0.5 + 0.45 * np.sin(a)] for a in np.arange(6) * np.pi / 3]
U_SHAPE = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.8], [0.7, 0.8], [0.7, 0.3], [0.3, 0.3], [0.3, 0.8],
           [0.0, 0.8]]  # fmt: skip


def scenario(
    polygon,
    motion: dict,
    kinds: str = "oodood",
    start=(2.0, 3.0, 0.0),
    obstacles=(),
    seed: int = 1,
    backend: str = "ideal",
):
    cfg = base_config_dict()
    cfg["object"]["polygon"] = [list(map(float, p)) for p in polygon]
    cfg["object"]["start"] = list(start)
    cfg["object"]["motion"] = {**cfg["object"]["motion"], **motion}
    cfg["obstacles"] = [{"polygon": o} for o in obstacles]  # the object's path stays clear
    for r, k in zip(cfg["robots"], kinds, strict=True):
        r["kind"] = "omni" if k == "o" else "diff"
    cfg = deep_update(cfg, {"sim": {"backend": backend, "seed": seed}, "capture": {"seed": seed}})
    port = free_port()
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    from controller.config import parse_config

    return parse_config(cfg, f"scenario-{seed}")


# an obstacle between the robots on the west wall and an object at (3, 3)
WALL = [[1.6, 2.6], [1.9, 2.6], [1.9, 4.6], [1.6, 4.6]]

SCENARIOS = {
    "L-sine-default": (L_SHAPE, {"kind": "sine", "speed": 0.06}, "oodood", (2.0, 3.0, 0.0), ()),
    "rect-line": (RECT, {"kind": "line", "speed": 0.1, "heading": 0.5}, "oodood", (2.5, 3.0, 0.3), ()),
    "rect-line-fast": (RECT, {"kind": "line", "speed": 0.2, "heading": 0.0}, "oooooo", (2.0, 3.0, 0.0), ()),
    "L-evade": (L_SHAPE, {"kind": "evade", "max_speed": 0.15, "flee_radius": 1.5}, "oodood", (3.0, 3.0, 0.0), ()),
    "hexagon-line-diff": (HEXAGON, {"kind": "line", "speed": 0.08, "heading": 1.0}, "dddddd", (2.5, 2.5, 0.0), ()),
    "L-rotated-line": (L_SHAPE, {"kind": "line", "speed": 0.12, "heading": 0.5}, "dodood", (3.0, 3.5, 2.0), ()),
    "rect-obstacle": (RECT, {"kind": "sine", "speed": 0.05}, "oodood", (3.0, 3.2, 0.0), (WALL,)),
    "T-sine": (T_SHAPE, {"kind": "sine", "speed": 0.1, "amplitude": 0.5}, "oodood", (2.5, 2.5, 0.0), ()),
    "U-sine": (U_SHAPE, {"kind": "sine", "speed": 0.08}, "oooddd", (2.5, 3.0, 0.0), ()),
    "T-evade-diff": (T_SHAPE, {"kind": "evade", "max_speed": 0.2, "flee_radius": 1.2}, "dddood", (3.0, 2.5, 0.5), ()),
    "L-line-obstacle": (L_SHAPE, {"kind": "line", "speed": 0.08, "heading": 0.2}, "oooddd", (2.6, 3.0, 0.0), (WALL,)),
}  # fmt: skip
