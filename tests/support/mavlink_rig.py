"""MAVLink test rig: configs of MAVLink robots and a lockstep fake clock + world + emulators."""

from __future__ import annotations

import signal
import socket
from pathlib import Path
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


def emulated_vehicle_config(folder: Path, profile: str) -> tuple[Path, FleetConfig]:
    """A config file of one MAVLink robot ``r`` of ``profile`` on a free loopback port (for a
    real-time emulator and `fleet driver`), and the parsed config the emulator is built from."""
    from tests.support.config import write_toml

    data = {
        "fleet": {"name": "t"},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{free_udp_port()}"]},
        "object": {
            "polygon": [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]],
            "start": [8.0, 8.0, 0.0],
            "motion": {"kind": "static"},
        },
        "sim": {"backend": "ideal", "timestep": 0.01},
        "robots": [robot("r", profile, free_udp_port(), 1)],
    }
    return write_toml(folder / f"{profile}.toml", data), make_config(data["robots"])


def strict_driver_exit(path: Path, emu: VehicleEmulator) -> int:
    """`fleet driver r --strict` against the started emulator ``emu``: its exit code (the
    emulator stopped and the signal handlers `fleet driver` installs restored afterwards)."""
    from controller.cli import main

    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return main(["driver", "r", "--config", str(path), "--strict", "--connect-timeout", "3"])
    finally:
        emu.stop()
        for s, h in handlers.items():
            signal.signal(s, h)
