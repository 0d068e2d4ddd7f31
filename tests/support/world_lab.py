"""The lab rehearsal of the world tests (``fleet world``, the daemon and the agents as processes):
its config and the daemon's status (shared by tests/integration/test_world_lab.py,
test_world_ros2.py and test_world_vehicles.py)."""

from __future__ import annotations

import tomllib

from tests.support.config import base_config_dict, write_toml
from tests.support.lab import fleet_json

ROBOTS = ("r1", "r2", "r3", "r4")


def rehearsal_config(tmp_path, port: int):
    """Four robots around a small crate creeping east: the arrest comes in about 10 s. The
    object has a goal but the transport waits 120 s, so the daemon holds after the arrest."""
    cfg = base_config_dict()
    cfg["robots"] = cfg["robots"][:4]
    # one robot on each side of the crate: no robot has to cross another's way, also when a
    # restarted daemon re-plans from where they stand
    starts = ([3.4, 2.2, 1.57], [4.4, 3.2, 3.14], [3.2, 4.3, -1.57], [2.1, 3.3, 0.0])
    for r, start in zip(cfg["robots"], starts, strict=True):
        r["start"] = start
    cfg["object"].update(
        polygon=[[0.0, 0.0], [0.6, 0.0], [0.6, 0.4], [0.0, 0.4]],
        start=[3.0, 3.0, 0.0],
        goal=[8.0, 8.0, 0.0],
        motion={"kind": "line", "speed": 0.03, "heading": 0.0, "max_force": 4.0},
    )
    cfg["transport"]["start_after"] = 120.0
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    # ideal backend at 60 Hz physics: the world stays a small share of the 2 cores
    cfg["sim"].update(backend="ideal", world="process", timestep=1.0 / 60.0, seed=3)
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "rehearsal.toml", cfg), cfg["fleet"]


SIX = ((3.3, 1.6, 1.57), (4.7, 3.2, 3.14), (3.3, 4.6, -1.57), (1.7, 3.2, 0.0),
       (4.6, 1.8, 2.36), (1.8, 4.5, -0.79))  # fmt: skip
GOAL = [4.5, 3.0, 0.0]  # about 1.2 m east of where the crate is arrested (CI time is tight)


def six_around(tmp_path, port: int) -> dict:
    """The rehearsal world with six robots around the crate (the first four the rehearsal's
    kinds; ``SIX`` starts) and the crate's goal a short way east (capture, route,
    re-arrangement and transport all in it), as data: the mixed fleet's world
    (test_world_vehicles.py) and its dry-run twin (test_transport_scenarios.py)."""
    path, _ = rehearsal_config(tmp_path, port)
    data = tomllib.loads(path.read_text())
    robots = base_config_dict()["robots"][:6]
    for r, start in zip(robots, SIX, strict=True):
        r["start"] = list(start)
    data["robots"] = robots
    data["object"]["goal"] = GOAL
    data["transport"]["start_after"] = 5.0
    return data


def daemon_status(cfg) -> dict:
    """``fleet status --json`` of the config's fleet (``{"ok": False}`` when none answers)."""
    code, st = fleet_json("status", "--config", str(cfg), "--timeout", "1")
    return st if code == 0 else {"ok": False}


def all_present(st: dict, ids: set[str] = set(ROBOTS)) -> bool:  # noqa: B006 - read only
    """Whether the daemon answers and sees every robot of ``ids`` present, poses arriving."""
    present = {r["id"] for r in st.get("robots", []) if r.get("present")}
    return bool(st.get("ok")) and present >= ids and st["counters"].get("poses", 0) > 0
