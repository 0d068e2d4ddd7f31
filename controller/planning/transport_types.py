"""Types of the transport local planners: what the mission passes in, what it gets back.

Frames and units: world poses (x m, y m, θ rad); "object frame" is the frame of the polygon as
written in ``object.polygon`` (counter-clockwise); forces N; speeds m/s; times s. Robots are
identified by their index in ``TransportState.robots``.

The actions of one robot in one interval (a column of Vass's relative-velocity matrix V, here
rows are intervals and columns robots):

- ``push``: stays on its contact point and pushes (its normal force is an LP unknown);
- ``follow``: stays on its contact point, passive (zero force): it rides along with the object;
- ``slide_left`` / ``slide_right``: passive, slides along the boundary at ``slide_speed`` to its
  own left / right as it faces the object (left is clockwise along the CCW boundary);
- ``relocate``: leaves the contact, travels around the object on a lane outside the robots
  (``ObjectModel.lane``) to the contact point the relocation scan chose, and arrives after
  path length / max_speed; the V entries of the intervals it spends travelling are ignored;
- ``idle``: stands still in the world, zero force (it loses contact if the object moves away,
  and is hit if the object moves into it).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from controller.config import TRANSPORT_STRATEGIES, TransportSection, configured, from_section

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

ACTIONS = ("push", "follow", "slide_left", "slide_right", "relocate", "idle")
PUSH, FOLLOW, SLIDE_LEFT, SLIDE_RIGHT, RELOCATE, IDLE = range(len(ACTIONS))
ATTACHED = (PUSH, FOLLOW, SLIDE_LEFT, SLIDE_RIGHT)  # actions that keep a contact

# the transport.strategy names (one registry: controller.config; their strategies:
# controller.planning.transport.LOCAL_STRATEGIES)
STRATEGIES = TRANSPORT_STRATEGIES
SCHEDULES = ("geometric", "logarithmic")


def action_code(name: str) -> int:
    """The index of an action name in :data:`ACTIONS` (ValueError naming the valid ones)."""
    try:
        return ACTIONS.index(name)
    except ValueError:
        raise ValueError(f"unknown action {name!r}; expected one of {ACTIONS}") from None


@dataclass(frozen=True, eq=False)
class RobotState:
    """One robot as the planner sees it.

    position: (2,) world centre (m); radius (m); max_force (N, the most it can push with);
    max_speed (m/s); contact: None, or (point, inward normal) in the object frame (the point on
    the boundary it touches, the unit direction it pushes in); action: the action it executed in
    the last interval (for the action-change term), None if none; id: for messages only;
    target: the contact (point, inward normal) a robot already on its way is relocating to
    (the mission commits to a relocation until the robot arrives), None if none.
    """

    position: FloatArray
    radius: float
    max_force: float
    max_speed: float
    contact: tuple[FloatArray, FloatArray] | None = None
    action: str | None = None
    id: str = ""
    target: tuple[FloatArray, FloatArray] | None = None


@dataclass(frozen=True, eq=False)
class RouteSegment:
    """The part of the object route the local planner works on.

    waypoints: (k, 3) object-frame poses along the route (m, m, rad), e.g. the route planner's
    ``RouteResult.waypoints`` from where the object is to the goal; subgoal: index into
    ``waypoints`` of the current subgoal (the plan never drives past it; default: the last).
    Deviation is measured from the path the object's centroid takes along the waypoints;
    progress along it in "pose arc length": centroid distance plus mean radius × turned angle.
    """

    waypoints: FloatArray
    subgoal: int = -1

    @classmethod
    def toward(cls, waypoints: FloatArray, subgoal_pose: FloatArray) -> RouteSegment:
        """The segment whose subgoal is the waypoint nearest to ``subgoal_pose`` (e.g. one of
        the route planner's ``RouteResult.subgoals``, which are waypoints)."""
        wp = np.asarray(waypoints, float)
        g = np.asarray(subgoal_pose, float)
        d = np.linalg.norm(wp[:, :2] - g[:2], axis=1)
        d = d + 1e-3 * np.abs((wp[:, 2] - g[2] + np.pi) % (2 * np.pi) - np.pi)
        return cls(wp, int(np.argmin(d)))


@dataclass(frozen=True, eq=False)
class TransportState:
    """Everything one local plan starts from (the mission builds it from the filtered poses).

    model: the object (:class:`controller.planning.transport_model.ObjectModel`: polygon, mass,
    floor and contact friction, boundary nodes; built once per mission); pose: (3,) world pose
    of the object frame; robots: one :class:`RobotState` each; route: the segment to follow;
    obstacles: world polygons (n, 2) the object and robots must not touch; bounds: optional
    [[xmin, ymin], [xmax, ymax]] the robots must stay in; serpentine_group: the group that was
    pushing in the last interval (serpentine only; None: choose by the deviation rule).
    """

    model: Any  # ObjectModel (typed loosely to keep this module free of the model's imports)
    pose: FloatArray
    robots: tuple[RobotState, ...]
    route: RouteSegment
    obstacles: tuple[FloatArray, ...] = ()
    bounds: FloatArray | None = None
    serpentine_group: int | None = None


_TRANSPORT = TransportSection()  # the config's defaults


@dataclass(frozen=True)
class TransportParams:
    """Local-planner parameters, built in one place from ``[transport]``
    (:meth:`from_config`), each default the section's (``configured``: written once, in the
    config). Units: s, m, m/s, N; weights per unit named in the config."""

    strategy: str = configured(_TRANSPORT, "strategy")
    intervals: int = configured(_TRANSPORT, "intervals")
    interval: float = configured(_TRANSPORT, "interval")
    iterations: int = configured(_TRANSPORT, "iterations")
    initial_temperature: float = configured(_TRANSPORT, "initial_temperature")
    cooling: float = configured(_TRANSPORT, "cooling")
    schedule: str = configured(_TRANSPORT, "schedule")
    initial_actions: str = configured(_TRANSPORT, "initial_actions")
    block_moves: float = configured(_TRANSPORT, "block_moves")
    speed: float = configured(_TRANSPORT, "speed")
    lookahead: float = configured(_TRANSPORT, "lookahead")
    slide_speed: float = configured(_TRANSPORT, "slide_speed")
    push_bias: float = configured(_TRANSPORT, "push_bias")
    relocation_spacing: float = configured(_TRANSPORT, "relocation_spacing")
    k_collision: float = configured(_TRANSPORT, "k_collision")
    k_equilibrium: float = configured(_TRANSPORT, "k_equilibrium")
    k_force: float = configured(_TRANSPORT, "k_force")
    k_change: float = configured(_TRANSPORT, "k_change")
    k_deviation: float = configured(_TRANSPORT, "k_deviation")
    k_progress: float = configured(_TRANSPORT, "k_progress")
    serpentine_deviation: float = configured(_TRANSPORT, "serpentine_deviation")
    serpentine_min_deviation: float = configured(_TRANSPORT, "serpentine_min_deviation")
    # the error model (``transport.errors``, Yamashita's condition 2; 0: condition 1): m of a
    # robot's motion error (the norm of errors.position) and of the centre of mass's (per axis)
    pose_error: float = configured(_TRANSPORT, "errors", lambda e: math.hypot(*e.position))
    com_error: float = configured(_TRANSPORT, "errors", lambda e: float(e.com))
    contact_tolerance: float = 0.01  # m: closer counts as touching, deeper as a collision

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ValueError(f"strategy: expected one of {STRATEGIES}, got {self.strategy!r}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule: expected one of {SCHEDULES}, got {self.schedule!r}")
        if self.intervals < 1 or self.iterations < 0 or self.interval <= 0:
            raise ValueError("intervals >= 1, iterations >= 0 and interval > 0 expected")

    @classmethod
    def from_config(cls, t: Any, **overrides: Any) -> TransportParams:
        """From a ``TransportSection`` (controller.config); ``overrides`` replace fields."""
        params = from_section(cls, t)
        return dataclasses.replace(params, **overrides) if overrides else params


@dataclass(frozen=True)
class Energy:
    """The energy of one action matrix and its terms (raw, before the weights K).

    collisions: intervals with a collision (count); infeasible: intervals whose LP has no
    answer (count); force: Σ over intervals and robots of |f| (N); changes: action changes
    (count); deviation: Σ over intervals of the centroid's distance from the route (m);
    progress: pose arc length gained along the route over the plan (m). total = K_c·collisions
    + K_e·infeasible + K_f·force + K_g·changes + K_d·deviation − K_p·progress.
    """

    total: float
    collisions: int
    infeasible: int
    force: float
    changes: int
    deviation: float
    progress: float

    def to_dict(self) -> dict[str, float]:
        return {k: round(float(v), 6) for k, v in self.__dict__.items()}


@dataclass(frozen=True, eq=False)
class LocalPlan:
    """One local plan (the mission executes the first interval and plans again).

    strategy; status: "ok" or "at_subgoal" (nothing left to do on this segment);
    interval: the plan's interval length dt (s; Vass: the time to the subgoal at ``speed``
    over the number of intervals, never below ``TransportParams.interval``);
    matrix: (intervals, robots) the chosen action matrix V (codes into ACTIONS);
    effective: (intervals, robots) what the kinematic model did with it (travelling
    relocators, robots without contact);
    first_actions: per robot, the action name of the first interval;
    velocities: (robots, 2) world velocity command for the first interval (m/s);
    contact_points, contact_normals: (robots, 2) object-frame contact point and inward normal
    each robot should hold at the end of the first interval, or its relocation target (NaN if
    none);
    object_poses: (intervals + 1, 3) predicted world poses of the object frame;
    object_twists: (intervals, 3) predicted world twist of the centroid (m/s, m/s, rad/s);
    forces: (intervals, robots) contact normal forces (N); lp_status, lp_reason: per interval;
    energy: the chosen matrix's :class:`Energy`; start_energy: that of the starting matrix;
    iterations, accepted: annealing statistics;
    serpentine_group: the group pushing in the first interval (serpentine; else None);
    serpentine_groups: how many of the two groups have members (serpentine; else None);
    relocation_targets: robot index → object-frame point the scan picked (only for robots the
    plan considered relocating).
    """

    strategy: str
    status: str
    interval: float
    matrix: IntArray
    effective: IntArray
    first_actions: tuple[str, ...]
    velocities: FloatArray
    contact_points: FloatArray
    contact_normals: FloatArray
    object_poses: FloatArray
    object_twists: FloatArray
    forces: FloatArray
    lp_status: tuple[str, ...]
    lp_reason: tuple[str, ...]
    energy: Energy
    start_energy: Energy
    iterations: int = 0
    accepted: int = 0
    serpentine_group: int | None = None
    relocation_targets: dict[int, FloatArray] = field(default_factory=dict)
    serpentine_groups: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the ``plan/transport`` message and the MCAP log."""

        def arr(a: np.ndarray, nd: int = 6) -> list:
            out = np.round(np.asarray(a, float), nd).astype(object)
            out[~np.isfinite(np.asarray(a, float))] = None
            return out.tolist()

        return {
            "strategy": self.strategy,
            "status": self.status,
            "interval": self.interval,
            "actions": [[ACTIONS[int(c)] for c in row] for row in self.effective],
            "matrix": self.matrix.tolist(),
            "first_actions": list(self.first_actions),
            "velocities": arr(self.velocities),
            "contact_points": [None if p[0] is None else p for p in arr(self.contact_points)],
            "object_poses": arr(self.object_poses),
            "forces": arr(self.forces, 4),
            "lp_status": list(self.lp_status),
            "lp_reason": list(self.lp_reason),
            "energy": self.energy.to_dict(),
            "start_energy": self.start_energy.to_dict(),
            "iterations": self.iterations,
            "accepted": self.accepted,
            "serpentine_group": self.serpentine_group,
            "serpentine_groups": self.serpentine_groups,
        }
