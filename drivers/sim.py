"""The sim driver: the driver contract over a stand-in world (pybullet or ideal) via a SimHub.

Commands go to the world as body-frame velocity targets; poses come from the hub's sensors with
their own sim-time stamps. ``fail_link()`` simulates a lost link (for tests of the agent).
"""

from __future__ import annotations

from controller.wire import PoseMeasurement, Twist2D
from drivers.base import Capabilities, ConnectTimeout, LinkHealth, LinkLost
from sim_backend.hub import SimHub


class SimDriver:
    """One robot of a simulated world behind the driver contract."""

    def __init__(
        self,
        hub: SimHub,
        robot_id: str,
        capabilities: Capabilities,
        sigma_xy: float = 0.0,
        sigma_theta: float = 0.0,
        time_offset: float = 0.0,
    ) -> None:
        """``time_offset`` (s) is added to sim time in pose stamps (e.g. the wall-clock start
        time when the world runs in real time beside a lab daemon)."""
        self.hub = hub
        self.robot_id = robot_id
        self.capabilities = capabilities
        self._sigma = (sigma_xy, sigma_theta)
        self._connected = False
        self._lost = ""
        self._seq = 0
        self._offset = time_offset

    def connect(self, timeout: float) -> None:
        if self.robot_id not in self.hub.world.robot_ids:
            raise ConnectTimeout(f"robot {self.robot_id!r} is not in the sim world")
        self._connected = True

    def send(self, cmd: Twist2D) -> None:
        if self._lost:
            raise LinkLost(f"robot {self.robot_id}: {self._lost}")
        if not self._connected:
            raise LinkLost(f"robot {self.robot_id}: not connected")
        self.hub.world.set_command(self.robot_id, cmd.vx, cmd.vy, cmd.wz)

    def poll(self) -> list[PoseMeasurement]:
        if self._lost or not self._connected:
            return []
        out = []
        for t, x, y, th in self.hub.take_robot(self.robot_id):
            self._seq += 1
            out.append(
                PoseMeasurement(
                    t=t + self._offset,
                    seq=self._seq,
                    x=x,
                    y=y,
                    theta=th,
                    sigma_xy=self._sigma[0],
                    sigma_theta=self._sigma[1],
                    source="sim",
                )
            )
        return out

    def stop(self) -> None:
        if self._connected:
            self.hub.world.set_command(self.robot_id, 0.0, 0.0, 0.0)

    def health(self) -> LinkHealth:
        if self._lost:
            return LinkHealth(False, self._lost)
        return LinkHealth(self._connected, "" if self._connected else "not connected")

    def fail_link(self, detail: str = "simulated link loss") -> None:
        """Make the link fail as a real one would (the robot keeps its last command)."""
        self._lost = detail

    def restore_link(self) -> None:
        """The link comes back (after ``fail_link``)."""
        self._lost = ""

    def close(self) -> None:
        self.stop()
        self._connected = False
