"""The interface every stand-in world implements (pybullet physics or the ideal kinematic one).

A world knows nothing of the bus. Poses are world-frame (x, y, theta) arrays in metres and
radians; commands are body-frame (vx forward, vy left, wz CCW). ``step`` advances sim time;
all time is sim time. Sensors (noise, rates, dropouts) live in ``sim_backend.sensors`` and wrap
any world.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class WorldCheck:
    """Ground-truth safety figures of the current state (for the dry run's verdict).

    ``min_clearance`` is min over robot pairs of centre distance - r_i - r_j (m);
    ``object_penetration`` the deepest robot overlap with the object (m, 0 if none);
    ``obstacle_contacts`` the robot ids touching a static obstacle or wall;
    ``object_clearance`` the object polygon's distance to obstacles and walls (m, negative when
    it overlaps one or leaves the room).
    """

    min_clearance: float
    object_penetration: float
    obstacle_contacts: tuple[str, ...]
    object_clearance: float = float("inf")


class World(Protocol):
    """A planar world of disc robots, one polygonal object and static obstacles."""

    @property
    def t(self) -> float:
        """Sim time (s)."""
        ...

    @property
    def robot_ids(self) -> tuple[str, ...]: ...

    def set_command(self, robot_id: str, vx: float, vy: float, wz: float) -> None:
        """Body-frame velocity target; a differential robot ignores vy."""
        ...

    def step(self, duration: float) -> None:
        """Advance the world by ``duration`` seconds (rounded to whole physics steps)."""
        ...

    def robot_pose(self, robot_id: str) -> np.ndarray:
        """True (x, y, theta) of a robot."""
        ...

    def robot_velocity(self, robot_id: str) -> np.ndarray:
        """True world-frame (vx, vy, wz) of a robot."""
        ...

    def object_pose(self) -> np.ndarray:
        """True (x, y, theta) of the object frame."""
        ...

    def object_velocity(self) -> np.ndarray:
        """True world-frame (vx, vy, wz) of the object frame origin."""
        ...

    def contact_forces(self) -> dict[str, float]:
        """Normal force (N) each robot in contact presses on the object with (truth; empty
        where the world has no forces)."""
        ...

    def hold_object(self) -> None:
        """The object's drive holds its start pose (its path not begun) until
        :meth:`start_object`."""
        ...

    def start_object(self) -> None:
        """The object's path begins now (a no-op once begun)."""
        ...

    @property
    def object_waiting(self) -> bool:
        """Whether the object's path has not begun (:meth:`hold_object`)."""
        ...

    @property
    def object_alive(self) -> bool:
        """Whether the object's own drive is still on. It goes limp ("compromised": it moves
        only when pushed) by itself, after fighting a hold or a wall for a while
        (``object.motion.give_up_after``); nothing the controller says changes that."""
        ...

    @property
    def object_gave_up_at(self) -> float | None:
        """Sim time (s) the object went limp, None while it is alive."""
        ...

    def check(self) -> WorldCheck:
        """Safety figures of the current true state."""
        ...

    def close(self) -> None: ...
