"""Seeded transport scenarios: configs where the robots already hold the object (``fleet run
--mission transport``) or, for the whole job, start around the room. Shared by the transport
suite (tests/scenarios/test_transport_scenarios.py) and bench/transport.py."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig, parse_config
from tests.support.config import base_config_dict, deep_update, free_port

L_SHAPE = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]]
CRATE = [[0.0, 0.0], [0.8, 0.0], [0.8, 0.5], [0.0, 0.5]]


@dataclass(frozen=True)
class Scenario:
    """A transport scenario: object, where it starts and goes, the room, the fleet."""

    name: str
    polygon: list
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    backend: str = "ideal"
    kinds: str = "oodood"  # one letter per robot: omni or diff
    obstacles: tuple = ()
    bounds: tuple = ((0.0, 0.0), (8.0, 6.0))
    mass: float = 4.0
    floor_friction: float = 0.2
    max_force: float = 6.0
    max_speed: float = 0.4
    whole_job: bool = False  # capture a moving object first (else the robots hold it)
    motion: dict = field(default_factory=lambda: {"kind": "inert"})  # a plain crate
    seed: int = 1
    max_time: float = 200.0
    patch: dict = field(default_factory=dict)


def holding_starts(cfg_dict: dict[str, Any], n: int) -> list[list[float]]:
    """Robot start poses touching the capture set the planner would pick for this object (the
    GA's set reinforced to hold), placed at the object's start: a fleet that already holds it."""
    from controller.mission.job import plan_capture_set

    cfg = parse_config(cfg_dict, "scenario")
    cap = plan_capture_set(cfg, np.random.default_rng(cfg.capture.seed))
    r = cfg.max_robot_radius
    centres = geometry.transform(cap.points + (r + 0.001) * cap.normals, cfg.object.start)
    inward = -cap.normals @ geometry.rot(float(cfg.object.start[2])).T
    heading = np.arctan2(inward[:, 1], inward[:, 0])  # a diff robot faces what it pushes
    starts = [[float(x), float(y), float(h)] for (x, y), h in zip(centres, heading, strict=True)]
    if len(starts) > n:
        raise ValueError(f"the capture set needs {len(starts)} robots, the scenario has {n}")
    (x0, y0), (x1, y1) = cfg.world.bounds
    spare = [[x0 + 0.3 + 0.4 * k, y0 + 0.3, 0.0] for k in range(n - len(starts))]
    return starts + spare


def scenario_config(sc: Scenario, port: int | None = None) -> FleetConfig:
    """The config of a scenario, on a free loopback port."""
    return parse_config(scenario_dict(sc, port), f"scenario:{sc.name}")


def scenario_dict(sc: Scenario, port: int | None = None) -> dict[str, Any]:
    """The config of a scenario as data (what ``scenario_config`` parses)."""
    d = copy.deepcopy(base_config_dict())
    d["world"] = {"bounds": [list(b) for b in sc.bounds], "walls": True}
    d["obstacles"] = [{"polygon": [list(p) for p in o]} for o in sc.obstacles]
    d["object"].update(
        {
            "polygon": sc.polygon,
            "start": list(sc.start),
            "goal": list(sc.goal),
            "mass": sc.mass,
            "floor_friction": sc.floor_friction,
            "motion": sc.motion,
        }
    )
    d["robots"] = [
        {
            "id": f"r{k + 1}",
            "kind": "omni" if c == "o" else "diff",
            "radius": 0.1,
            "max_speed": sc.max_speed,
            "max_yaw_rate": 2.0,
            "max_force": sc.max_force,
            "driver": "sim",
            "start": [0.3 + 0.4 * k, 0.3, 0.0],
        }
        for k, c in enumerate(sc.kinds)
    ]
    d["capture"] = {**d.get("capture", {}), "seed": sc.seed}
    d["sim"] = {**d["sim"], "backend": sc.backend, "seed": sc.seed, "max_time": sc.max_time}
    d = deep_update(d, sc.patch)
    if not sc.whole_job:
        for r, s in zip(d["robots"], holding_starts(d, len(d["robots"])), strict=True):
            r["start"] = s
    p = port or free_port()
    d["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{p}"], "connect": []}
    return d


# the transport suite (tests/scenarios/test_transport_scenarios.py): each reachable scenario
# delivers; the too-heavy crate and the unreachable goal fail at once, with their reasons
LONG_CRATE = [[0.0, 0.0], [0.6, 0.0], [0.6, 1.2], [0.0, 1.2]]  # pushed along x: a 1.2 m back
TRAPEZOID = [[0.0, 0.0], [1.2, 0.0], [0.9, 0.6], [0.3, 0.6]]

ROOM = ((0.0, 0.0), (8.0, 6.0))
PILLAR = ((3.6, 1.2), (4.0, 1.2), (4.0, 1.6), (3.6, 1.6))
WALL_WITH_DOOR = (  # a wall across the room at x = 4 with a door 1.8 m wide
    ((3.9, 0.0), (4.1, 0.0), (4.1, 2.1), (3.9, 2.1)),
    ((3.9, 3.9), (4.1, 3.9), (4.1, 6.0), (3.9, 6.0)),
)
ENCLOSURE = (  # a closed pen around the goal
    ((5.5, 3.5), (7.5, 3.5), (7.5, 3.7), (5.5, 3.7)),
    ((5.5, 5.3), (7.5, 5.3), (7.5, 5.5), (5.5, 5.5)),
    ((5.5, 3.5), (5.7, 3.5), (5.7, 5.5), (5.5, 5.5)),
    ((7.3, 3.5), (7.5, 3.5), (7.5, 5.5), (7.3, 5.5)),
)

SCENARIOS = [
    Scenario("open-floor-ideal", CRATE, (1.5, 2.5, 0.0), (5.5, 3.0, 0.0)),
    Scenario(
        "obstacle-beside-route", L_SHAPE, (1.5, 1.0, 0.0), (5.5, 1.5, 0.0), obstacles=(PILLAR,)
    ),
    # the door in pybullet only (real contacts, force-limited pushes through a 1.8 m gap); the
    # ideal world's copy of it repeated the same route in the slower kinematic push model (44 s)
    Scenario(
        "doorway-pybullet",
        L_SHAPE,
        (1.5, 2.5, 0.0),
        (5.5, 2.5, 0.0),
        obstacles=WALL_WITH_DOOR,
        backend="pybullet",
    ),
    Scenario(
        "moving-when-captured",
        L_SHAPE,
        (2.0, 2.5, 0.0),
        (5.0, 3.0, 0.0),
        whole_job=True,
        motion={"kind": "sine", "speed": 0.06, "amplitude": 0.3, "wavelength": 4.0},
    ),
    Scenario("open-floor-pybullet", CRATE, (1.5, 2.5, 0.0), (5.0, 3.0, 0.0), backend="pybullet"),
    Scenario("turn-180-pybullet", CRATE, (2.0, 2.5, 0.0), (3.5, 3.0, 3.14159), backend="pybullet"),
    Scenario(
        "heavy-pybullet",  # 29 N of floor friction for robots of 8 N: four pushers at 92 % of
        LONG_CRATE,  # their limit, on a back edge where five fit
        (1.5, 2.5, 0.0),
        (4.0, 2.5, 0.0),
        backend="pybullet",
        kinds="oooooooo",
        mass=10.0,
        floor_friction=0.3,
        max_force=8.0,
        patch={"capture": {"hold_force": 0.0}},
    ),
    Scenario(
        "diff-pushers-pybullet",
        CRATE,
        (1.5, 2.5, 0.0),
        (4.5, 2.5, 0.0),
        backend="pybullet",
        kinds="dddddd",
    ),  # fmt: skip
    # floor friction 14.4 N, 40 % of the six robots' 36 N; along x on its 0.5 m face only two
    # robots of 6 N fit: the route keeps to the ways the fleet can push (item 9 of issue 34)
    Scenario(
        "turned-crate-pybullet",
        CRATE,
        (1.5, 2.5, 0.0),
        (4.5, 2.5, 0.0),
        backend="pybullet",
        mass=4.89,
        floor_friction=0.3,
    ),
    # issue 34's heavy load: 47 N of floor friction for 8 robots of 15 N, of which only the
    # trapezoid's 1.2 m base takes enough to push it: turned a quarter turn and back
    Scenario(
        "heavy-trapezoid-pybullet",
        TRAPEZOID,
        (1.5, 2.5, 0.0),
        (5.0, 2.5, 0.0),
        backend="pybullet",
        kinds="oooooooo",
        mass=12.0,
        floor_friction=0.4,
        max_force=15.0,
        max_time=300.0,
        patch={"capture": {"hold_force": 0.0}},
    ),
]
TOO_HEAVY = Scenario(  # floor friction 29.4 N, 82 % of the six robots' 36 N, but at no heading
    "too-heavy-pybullet",  # do enough robots of 6 N fit on the faces that push it
    CRATE,
    (1.5, 2.5, 0.0),
    (4.5, 2.5, 0.0),
    backend="pybullet",
    mass=10.0,
    floor_friction=0.3,
)
UNREACHABLE = Scenario(
    "unreachable-goal", CRATE, (1.5, 2.0, 0.0), (6.1, 4.2, 0.0), obstacles=ENCLOSURE
)
