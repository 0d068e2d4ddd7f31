"""MAVLink test rig: configs of MAVLink robots and a lockstep fake clock + world + emulators."""

from __future__ import annotations

import socket
from typing import Any

from controller.config import FleetConfig, parse_config
from sim_backend.ideal import IdealWorld
from sim_backend.mavlink_vehicle import VehicleEmulator

H = 0.01  # s, lockstep step (the ideal world's timestep)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_config(robots: list[dict[str, Any]]) -> FleetConfig:
    return parse_config(
        {
            "fleet": {"name": "t"},
            "object": {
                "polygon": [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]],
                "start": [8.0, 8.0, 0.0],
                "goal": [9.0, 9.0, 0.0],
                "motion": {"kind": "static"},
            },
            "sim": {"backend": "ideal", "timestep": 0.01},
            "robots": robots,
        }
    )


def robot(rid: str, profile: str, port: int, system_id: int, theta: float = 0.6,
          **extra: Any) -> dict[str, Any]:  # fmt: skip
    return {
        "id": rid,
        "kind": "diff" if profile == "ardurover" else "omni",
        "start": [2.0 + system_id, 3.0, theta],
        "driver": "mavlink",
        "url": f"udpin:127.0.0.1:{port}",
        "system_id": system_id,
        "profile": profile,
        **extra,
    }


class Lockstep:
    """Fake clock + world + emulators advanced together in H steps."""

    def __init__(self, cfg: FleetConfig):
        self.t = 0.0
        self.world = IdealWorld(cfg)
        self.emulators: list[VehicleEmulator] = []

    def clock(self) -> float:
        return self.t

    def emulator(self, cfg, **kw: Any) -> VehicleEmulator:
        e = VehicleEmulator(self.world, cfg, clock=self.clock, **kw)
        self.emulators.append(e)
        return e

    def advance(self, dt: float) -> None:
        for _ in range(max(1, round(dt / H))):
            self.t += H
            self.world.step(H)
            for e in self.emulators:
                e.pump(self.t)

    def close(self) -> None:
        for e in self.emulators:
            e.stop()
