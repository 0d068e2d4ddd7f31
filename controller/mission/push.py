"""The transport's push stage (pure): the local plans (Vass's simulated annealing, its downhill
ablation or Sharma's serpentine, ``controller.planning.transport``) asked for every interval
off the tick, and the latest one executed every tick, closed on the current estimate."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.events import TransportEvent
from controller.mission.grip import Contact, Grip, RobotOrder
from controller.mission.planners import JobOwned, Planners, PlanSlot, spawn_rng
from controller.mission.types import Event, FleetView
from controller.planning.serpentine import passive_velocity
from controller.planning.transport import TransportPlanner, local_strategy
from controller.planning.transport_model import ObjectModel
from controller.planning.transport_types import (
    ATTACHED,
    FOLLOW,
    PUSH,
    RELOCATE,
    SLIDE_LEFT,
    SLIDE_RIGHT,
    LocalPlan,
    RouteSegment,
    TransportParams,
    TransportState,
    action_code,
)


class Pusher:
    """Local plans in, velocities out. ``stuck`` counts plans in a row whose first interval the
    contact-force LP could not solve (the contacts cannot push as the route asks)."""

    def __init__(
        self,
        cfg: FleetConfig,
        model: ObjectModel,
        params: TransportParams,
        planners: Planners,
        rng: np.random.Generator,
        contact_gain: float,
    ) -> None:
        self.cfg, self.model, self.params, self.rng = cfg, model, params, rng
        self.contact_gain = contact_gain  # 1/s, pull back onto the contact point
        self.planner = JobOwned(TransportPlanner(params))  # touched only by its jobs
        self._job = PlanSlot(planners, "transport")
        self._reset = False  # the next local plan starts afresh (a new segment)
        self.last_plan: LocalPlan | None = None
        self.plan_t: float | None = None
        self.plans = 0
        self.stuck = 0
        self.plan_energy: list[float] = []
        self.forces: list[float] = []
        # serpentine (Sharma §4.3): plans, those with both groups manned, group switches
        self.serpentine = {"plans": 0, "two_groups": 0, "switches": 0}
        self._group: int | None = None  # the group the last serpentine plan pushed with

    def forget(self) -> None:
        """A new segment or arrangement: the local plan starts afresh (the planner's warm
        start is reset by the next plan's job: only jobs touch the planner)."""
        self._job.cancel()
        self._reset = True
        self.last_plan = None
        self.plan_t = None
        self._group = None  # new groups: a change of group is no switch

    def due(self, t: float) -> bool:
        """Whether a new plan is to be asked for (every interval of the last one)."""
        if self._job.pending:
            return False
        return self.plan_t is None or (
            self.last_plan is not None and t - self.plan_t >= self.last_plan.interval - 1e-9
        )

    def request(self, view: FleetView, pose: np.ndarray, grip: Grip, segment: RouteSegment):
        """Ask for a local plan from the current estimate (off the tick); the robots execute
        the previous one meanwhile. ``plan_t`` is the state's time: the next plan is due one
        interval after it, however long this one takes to come."""
        cfg = self.cfg
        state = TransportState(
            self.model,
            pose,
            grip.robot_states(view),
            segment,
            tuple(cfg.obstacle_polygons()),
            cfg.bounds_array(),
        )
        elapsed = 0.0 if self.plan_t is None else view.t - self.plan_t
        reset, self._reset = self._reset, False
        self._job.request(
            view.t, plan_local, self.planner, state, spawn_rng(self.rng), elapsed, reset
        )
        self.plan_t = view.t

    def take(self, t: float) -> Any:
        """The plan asked for, once it has come (a ``PlanResult``), else None."""
        return self._job.take(t)

    def orders(self, plan: LocalPlan, grip: Grip, relocate_ok: bool) -> list[RobotOrder]:
        """A local plan has come: what its first interval tells each robot (its action, the
        contact it holds or the one it relocates to), for the grip to follow. ``relocate_ok``:
        the contacts held cannot push as asked (a relocation costs seconds of travel the
        kinematic model does not pay in full: robots leave their contacts only then)."""
        self.last_plan = plan
        self.plans += 1
        first_ok = plan.lp_status[0] == "optimal" if plan.lp_status else True
        self.stuck = 0 if first_ok or grip.moves else self.stuck + 1
        self.plan_energy.append(plan.energy.total)
        out = []
        for i in range(grip.n):
            if i in grip.lost:
                continue
            action = plan.first_actions[i]
            p, nv = plan.contact_points[i], plan.contact_normals[i]
            if i in grip.moves:  # committed to a relocation: it finishes it first
                out.append(RobotOrder(i, action))
                continue
            code = action_code(action)
            if np.all(np.isfinite(p)) and code in ATTACHED:
                out.append(RobotOrder(i, action, Contact(p.copy(), nv.copy()), "hold"))
            elif code == RELOCATE and np.all(np.isfinite(p)) and relocate_ok:
                out.append(RobotOrder(i, action, Contact(p.copy(), nv.copy()), "relocate"))
            elif code == RELOCATE:
                out.append(RobotOrder(i, "follow"))
            else:
                out.append(RobotOrder(i, action))
        self.forces.extend(float(x) for x in plan.forces[0] if x > 0)
        return out

    def planned(self, view: FleetView, grip: Grip, events: list[Event]) -> None:
        """The event of the plan the grip now follows (who relocates, how far)."""
        plan = self.last_plan
        if plan.serpentine_groups is not None:
            self._count_serpentine(plan)
        moving = {
            view.ids[i]: float(np.sum(np.linalg.norm(np.diff(np.asarray(p), axis=0), axis=1)))
            for i, p in grip.moves.items()
        }
        ids = [view.ids[i] for i in range(grip.n)]  # the plan's rows (the scene's pushers)
        lag = view.t - self.plan_t  # the state it was planned from is this old
        events.append(
            TransportEvent(
                t=view.t,
                robots=ids,
                plan=plan.to_dict(),
                relocating=moving,
                plan_age_s=round(lag, 6),
            )
        )

    def _count_serpentine(self, plan: LocalPlan) -> None:
        s = self.serpentine
        s["plans"] += 1
        s["two_groups"] += plan.serpentine_groups == 2
        g = plan.serpentine_group
        if g is not None:
            s["switches"] += self._group is not None and g != self._group
            self._group = g

    def serpentine_summary(self) -> dict:
        """The serpentine's counts for the run's summary (None for the other strategies)."""
        on = local_strategy(self.params.strategy).groups
        s = self.serpentine
        return {
            "serpentine_plans": s["plans"] if on else None,
            "serpentine_two_group_plans": s["two_groups"] if on else None,
            "serpentine_switches": s["switches"] if on else None,
        }

    def give_up(self, plans: int) -> None:
        """Count the contacts as unable to push (``plans`` failed plans): a re-arrangement."""
        self.stuck = plans

    def unstick(self) -> None:
        """A re-arrangement was asked for: the count of failed plans starts again."""
        self.stuck = 0

    def execute(self, view: FleetView, pose: np.ndarray, grip: Grip):
        """The plan's first interval, closed every tick: a robot holding a contact moves with
        the object's planned twist at its contact point plus a pull back onto the point (and,
        pushing, ``push_bias`` into the object); a relocating or idle one takes the plan's
        velocity. Returns (velocities (N, 2), touch (N,), the object's planned twist)."""
        plan = self.last_plan
        n = grip.n
        vel = np.zeros((n, 2))
        touch = np.zeros(n, bool)
        twist = plan.object_twists[0] if len(plan.object_twists) else np.zeros(3)
        centroid = geometry.transform(self.model.centroid[None], pose)[0]
        rot = geometry.rot(float(pose[2]))
        for i in range(n):
            code = action_code(plan.first_actions[i])
            c = grip.contacts[i]
            if i in grip.moves or i in grip.lost:
                continue  # on its committed path (below); a lost robot is told nothing
            if code not in ATTACHED or c is None or code in (SLIDE_LEFT, SLIDE_RIGHT):
                vel[i] = plan.velocities[i]
                touch[i] = code in ATTACHED
                continue
            r = self.cfg.robots[i].radius
            centre = geometry.transform((c.point - r * c.inward)[None], pose)[0]
            vmax = self.cfg.robots[i].max_speed
            if code == FOLLOW and local_strategy(plan.strategy).passive_followers:
                vel[i] = passive_velocity(
                    centre, view.poses[i, :2], rot @ c.inward, pose, view.object_velocity,
                    self.contact_gain, vmax,
                )  # fmt: skip
                touch[i] = True
                continue
            rel = centre - centroid
            v = twist[:2] + twist[2] * np.array([-rel[1], rel[0]])
            v = v + self.contact_gain * (centre - view.poses[i, :2])
            if code == PUSH:
                v = v + self.params.push_bias * (rot @ c.inward)
            speed = float(np.linalg.norm(v))
            vel[i] = v if speed <= vmax else v * vmax / speed
            touch[i] = True
        grip.follow_paths(view, pose, vel, touch)
        return vel, touch, twist


def plan_local(
    box: JobOwned,
    state: TransportState,
    rng: np.random.Generator,
    elapsed: float,
    reset: bool,
) -> LocalPlan:
    """Job ``transport``: one local plan by the ``TransportPlanner`` in ``box`` (its warm
    start reset first on a new segment). Only these jobs touch it, one at a time."""
    if reset:
        box.value.reset()
    return box.value.plan(state, rng, elapsed)
