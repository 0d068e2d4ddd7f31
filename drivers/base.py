"""The driver contract: what every robot link adapter (sim, ideal, MAVLink) implements.

A driver is one robot's link. It is written for real links: poses arrive asynchronously and
irregularly (``poll`` returns whatever arrived since the last call, possibly nothing), a link can
be lost (``health`` says so, ``send`` raises ``LinkLost``), and ``connect`` can time out
(``ConnectTimeout``). The agent (``drivers.agent``) binds one driver to the bus.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from controller.wire import PoseMeasurement, Twist2D


class DriverError(RuntimeError):
    """A robot link failed; the message names the robot and the link."""


class ConnectTimeout(DriverError):
    """The robot did not answer within the connect timeout."""


class LinkLost(DriverError):
    """The link to the robot was lost (no heartbeat, closed socket, sim gone)."""


@dataclass(frozen=True)
class Capabilities:
    """What a robot can do: ``holonomic`` (accepts vy), limits in m/s and rad/s, radius in m."""

    kind: str
    holonomic: bool
    max_speed: float
    max_yaw_rate: float
    radius: float


def capabilities_of(robot: Any) -> Capabilities:
    """A robot's capabilities from its ``[[robots]]`` entry (``controller.config.RobotConfig``),
    the one place they are derived: only an ``omni`` robot is holonomic (the config refuses an
    omni ArduRover, which GUIDED never moves sideways)."""
    return Capabilities(
        kind=robot.kind,
        holonomic=robot.kind == "omni",
        max_speed=robot.max_speed,
        max_yaw_rate=robot.max_yaw_rate,
        radius=robot.radius,
    )


@dataclass(frozen=True)
class LinkHealth:
    """Link state as the driver sees it: ``ok`` false means lost; ``detail`` says why."""

    ok: bool
    detail: str = ""
    last_heard: float | None = None


@runtime_checkable
class RobotDriver(Protocol):
    """One robot's link. All times in seconds on the driver's clock (sim time in the dry run)."""

    robot_id: str
    capabilities: Capabilities

    def connect(self, timeout: float) -> None:
        """Open the link; raise ConnectTimeout if the robot does not answer within ``timeout``."""
        ...

    def send(self, cmd: Twist2D) -> None:
        """Command a body-frame velocity (already clamped by the agent); raise LinkLost if lost."""
        ...

    def poll(self) -> list[PoseMeasurement]:
        """World-frame pose measurements received since the last call; never blocks."""
        ...

    def stop(self) -> None:
        """Command zero velocity now (watchdog, e-stop, shutdown). Never raises."""
        ...

    def health(self) -> LinkHealth:
        """Whether the link is alive."""
        ...

    def close(self) -> None:
        """Stop the robot and release the link. Idempotent."""
        ...
