"""The safety stage every phase's velocities pass through: acceleration limit, the CBF filter
(``controller.planning.safety``) against robots, obstacles, walls and the object, and the
tracking law that turns world velocities into body-frame commands.

Pure: arrays in, a ``MissionOutput`` out; its only state is the last filtered velocity (for the
acceleration limit) and the filter's warm start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.events import SafetyStopEvent
from controller.mission.tracking import RobotLimits, track_reversible_ends
from controller.mission.types import FleetView, Intent, MissionOutput, Phase
from controller.planning.approach import limit_accel
from controller.planning.safety import SafetyFilter

# the capture closing on the object: two robots both at it keep capture.clearance between them
# (contacts in a concave notch lie nearer each other than the safety margin); in transport
# every pair keeps the margin (the pushers move with the object, and the lab's estimates lag)
CLOSING_PHASES = (Phase.CLOSE_IN, Phase.HOLD, Phase.ARRESTED)

FAR = 1.0e3  # m: an unknown object's barrier is parked this far away (the pattern is fixed)


@dataclass
class GuardCounters:
    infeasible: int = 0  # filter calls that had to stop robots (QP infeasible)


class SafetyStage:
    """Filters nominal world velocities of the whole fleet, every tick, for every mission."""

    def __init__(self, cfg: FleetConfig) -> None:
        ap = cfg.approach
        self.limits = RobotLimits.from_config(cfg.robots)
        self.n = len(cfg.robots)
        self.radii = np.array([r.radius for r in cfg.robots], float)
        self.max_accel = np.minimum(self.limits.max_accel, ap.max_accel)
        self.dt = 1.0 / cfg.fleet.rate_hz
        self.obstacles = [geometry.ensure_ccw(p) for p in cfg.obstacle_polygons()]
        self.object_poly = geometry.ensure_ccw(cfg.object_polygon())
        self.filter = SafetyFilter(
            self.radii,
            self.limits.max_speed,
            cfg.bounds_array(),
            len(self.obstacles) + 1,
            margin=ap.safety_margin,
            axial=~self.limits.holonomic,
            close_margin=cfg.capture.clearance,
        )
        self.v_prev = np.zeros((self.n, 2))
        self.backward: np.ndarray | None = None  # each diff robot's end of its axis, kept
        self.counters = GuardCounters()

    def object_world(self, pose: np.ndarray | None) -> np.ndarray:
        """The object polygon at ``pose`` (parked far away when unknown)."""
        p = np.array([FAR, FAR, 0.0]) if pose is None else np.asarray(pose, float)
        return geometry.transform(self.object_poly, p)

    def apply(self, view: FleetView, intent: Intent) -> MissionOutput:
        """Body-frame commands for ``intent``: zero on e-stop or ``stop``; otherwise the nominal
        velocities, acceleration-limited, filtered, tracked; stale or absent robots and
        ``hold`` robots get exactly zero."""
        out = MissionOutput.of(np.zeros((self.n, 3)), intent)
        c, phase = intent.command, intent.report.phase
        if view.estop or c.stop:
            self.v_prev[:] = 0.0
            return out
        vel = limit_accel(c.velocities, self.v_prev, self.max_accel, self.dt)
        polys = self.obstacles + [self.object_world(c.object_pose)]
        exempt = np.zeros((self.n, len(polys)), bool)
        if c.touch is not None:
            exempt[:, -1] = c.touch
        stale = view.stale | ~view.present
        fixed = _fixed(stale, c.hold)
        motion = [None] * len(self.obstacles) + [view.object_velocity]
        overlap = np.full(self.n, c.overlap)
        res = self.filter.filter(
            view.poses[:, :2],
            vel,
            polys,
            exempt=exempt,
            stale=fixed,
            motion=motion,
            overlap=overlap,
            hold=c.touch if c.cage else None,
            # in every phase a robot inside a margin it cannot recover at once (squeezed by
            # the object against a wall or another robot) moves away or slides out; stopped,
            # the object could push it on (a pusher's contact is exempt, never relaxed)
            relax=True,
            headings=view.poses[:, 2],
            close=c.touch if phase in CLOSING_PHASES else None,
        )
        if res.stopped.any():
            self.counters.infeasible += 1
            robots = [view.ids[i] for i in np.flatnonzero(res.stopped)]
            out.events.append(SafetyStopEvent(robots=robots))
        self.v_prev = res.velocities
        cmds, self.backward = track_reversible_ends(
            view.poses, res.velocities, self.limits, aim=res.aim, backward=self.backward
        )
        if c.steady is not None:
            # a differential robot holding a contact resists sideways with its tyres and along
            # its axis with its motor; turning toward a few mm of error only lets go
            cmds[c.steady, 2] = 0.0
        if c.hold is not None:
            cmds[c.hold] = 0.0
        cmds[stale] = 0.0
        out.commands = cmds
        return out


def _fixed(stale: np.ndarray, hold: np.ndarray | None) -> np.ndarray:
    """The robots the filter takes as fixed: the stale ones, and those commanded exactly zero
    after it (``hold``): the others keep every barrier to them alone (filtered as movable, a
    held robot was given half of the avoiding, which it never did: a differential robot drove
    into a caging one in the README lab's close-in)."""
    fixed = stale.copy()
    if hold is not None:
        fixed[hold] = True
    return fixed
