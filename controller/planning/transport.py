"""Local transport planners: Vass's simulated annealing, its downhill ablation, Sharma's
serpentine baseline. Entry point: :func:`plan_local`, called every control interval from the
filtered object pose (closed loop: the mission executes the first interval and plans again).

- ``sa`` (Vass et al. §4, Code 1): the action matrix V (intervals × robots) over ``ACTIONS``;
  each iteration picks one entry at random, gives it a different random action, rolls the new
  matrix out on the kinematic model (:mod:`controller.planning.transport_model`, incremental
  from the changed interval) and accepts it if the energy does not rise, else with probability
  exp(−ΔE/T). Schedules: geometric T_r = T_0·cooling^r, or logarithmic T_r = c/log(1 + r)
  (Vass Eq. 4) with c = T_0·log 2 so that both start at T_0. The plan is the lowest-energy
  matrix seen (never worse than the start). Proposals: with probability ``block_moves`` the
  new action replaces the robot's whole row from the chosen interval on (V[j:, i] = x: one
  action change instead of two, our addition), else the single entry (Code 1). The start
  matrix: the previous plan shifted by the intervals elapsed (when given), else "hold": each
  robot repeats its last action (one without: push if its push has a component along the
  force the object needs, else follow; idle without contact), or "random" (Code 1 line 2).
- ``downhill``: the same proposals and energy, accepting only ΔE ≤ 0 (SA at T → 0; Vass §5).
- ``serpentine`` (Sharma et al. §4.3, as published: :mod:`controller.planning.serpentine`):
  the Eq. 5 pushers that push forward (within ≈ 75° of the route) are split into two groups,
  those pushing toward the left of the route and those pushing toward the right (robots
  pushing straight along it even out the counts). One group pushes (every member at its
  max_force along its normal), the other is passive: zero force in the LP, and in the mission
  it moves with the measured object, a few millimetres off its contact. The object moves
  along the normal of the limit surface at the group's wrench (``twist_for_wrench``) at
  ``speed``; it moves only if that wrench reaches the limit surface (else the interval is
  infeasible). The groups switch when the centroid is more than
  h = max(h_min, h_0 · remaining / route length) to the side the active group pushes toward,
  h_0 = ``serpentine_deviation``, h_min = ``serpentine_min_deviation``: the threshold shrinks
  toward the goal. Its plan is rolled out on the same model and scored with the same energy
  (the LP then gives the least forces for the motion the group makes).

Randomness only through the passed ``numpy.random.Generator``; the same state, parameters and
seed give the same plan.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controller import geometry
from controller.planning.contact_lp import ContactForceLP
from controller.planning.serpentine import serpentine, serpentine_groups
from controller.planning.transport_model import Rollout, Trace, hold_matrix, lp_matrix
from controller.planning.transport_types import (
    ACTIONS,
    FOLLOW,
    IDLE,
    PUSH,
    Energy,
    FloatArray,
    IntArray,
    LocalPlan,
    TransportParams,
    TransportState,
)


def temperature(params: TransportParams, r: int) -> float:
    """The annealing temperature at iteration r (0-based)."""
    if params.schedule == "logarithmic":
        return params.initial_temperature * math.log(2.0) / math.log(2.0 + r)
    return params.initial_temperature * params.cooling**r


def accept(delta: float, temp: float, downhill: bool, rng: np.random.Generator) -> bool:
    """Code 1, lines 9-12: a move that does not raise the energy is taken; an uphill one with
    probability exp(−ΔE/T) (never in the downhill ablation)."""
    if delta <= 0.0:
        return True
    if downhill or temp <= 0.0:
        return False
    return bool(rng.random() < math.exp(-delta / temp))


def initial_matrix(
    roll: Rollout,
    rng: np.random.Generator,
    previous: LocalPlan | None = None,
    shift: int = 1,
) -> IntArray:
    """The annealer's start: the previous plan shifted by ``shift`` intervals (its last row
    repeated; if its shape fits), else each robot holding its last action, or a uniformly
    random matrix (``initial_actions``)."""
    params = roll.params
    n, k = params.intervals, roll.k
    if (
        previous is not None
        and previous.matrix.shape == (n, k)
        and local_strategy(previous.strategy).warm_starts
    ):
        shift = min(max(int(shift), 0), n - 1)
        m = previous.matrix
        return np.vstack([m[shift:], np.repeat(m[-1:], shift, axis=0)]).astype(np.int64)
    if params.initial_actions == "random":
        return rng.integers(0, len(ACTIONS), size=(n, k)).astype(np.int64)
    if params.initial_actions == "lp":
        return lp_matrix(roll, n)
    return hold_matrix(roll, n)


def anneal(
    roll: Rollout, start: Trace, params: TransportParams, rng: np.random.Generator, downhill: bool
) -> tuple[Trace, int]:
    """Vass's Code 1 over ``params.iterations`` proposals; returns the lowest-energy trace seen
    and the number of accepted moves."""
    cur = start
    e_cur = roll.energy(cur).total
    best, e_best = cur, e_cur
    n, k = cur.matrix.shape
    n_act = len(ACTIONS)
    accepted = 0
    for r in range(params.iterations):
        j = int(rng.integers(n))
        i = int(rng.integers(k))
        x = int(rng.integers(n_act - 1))
        x += int(x >= cur.matrix[j, i])  # a different action
        m = cur.matrix.copy()
        if params.block_moves > 0 and rng.random() < params.block_moves:
            m[j:, i] = x  # the robot switches to x from interval j on
        else:
            m[j, i] = x  # Code 1: one entry
        cand = roll.rerun(cur, m, j)
        e_new = roll.energy(cand).total
        if accept(e_new - e_cur, temperature(params, r), downhill, rng):
            cur, e_cur = cand, e_new
            accepted += 1
            if e_cur < e_best:
                best, e_best = cur, e_cur
    return best, accepted


# --------------------------------------------------------------------------- the plan


def _first_interval(roll: Rollout, trace: Trace) -> tuple[FloatArray, FloatArray, FloatArray]:
    """World velocity commands (k, 2) for the first interval and the contact each robot should
    hold at its end (object-frame point and inward normal, NaN if none)."""
    m, p, st = roll.model, roll.params, roll.state
    s1 = trace.sims[1]
    now = np.array([np.asarray(r.position, float) for r in st.robots]).reshape(roll.k, 2)
    vel = (s1.pos - now) / roll.dt
    pts = np.full((roll.k, 2), np.nan)
    nrm = np.full((roll.k, 2), np.nan)
    rot = geometry.rot(s1.pose[2])
    for i in range(roll.k):
        node = s1.nodes[i]
        if node < 0 and s1.transit[i] is not None:
            node = s1.transit[i].target
        if node >= 0:
            pts[i], nrm[i] = m.nodes[node], -m.normals[node]
        if trace.effective[0][i] == PUSH and s1.nodes[i] >= 0:
            vel[i] += p.push_bias * (rot @ nrm[i])
        speed = float(np.linalg.norm(vel[i]))
        if speed > roll.vmax[i]:
            vel[i] *= roll.vmax[i] / speed
    return vel, pts, nrm


def make_plan(
    roll: Rollout,
    trace: Trace,
    start_energy: Energy,
    status: str,
    iterations: int = 0,
    accepted: int = 0,
    group: int | None = None,
) -> LocalPlan:
    """Package a trace as the :class:`LocalPlan` the mission reads."""
    vel, pts, nrm = _first_interval(roll, trace)
    eff = np.array(trace.effective, np.int64).reshape(len(trace.terms), roll.k)
    return LocalPlan(
        strategy=roll.params.strategy,
        status=status,
        interval=roll.dt,
        matrix=trace.matrix.copy(),
        effective=eff,
        first_actions=tuple(ACTIONS[int(a)] for a in eff[0]),
        velocities=vel,
        contact_points=pts,
        contact_normals=nrm,
        object_poses=np.array([roll.object_pose(s) for s in trace.sims]),
        object_twists=np.array(trace.twists),
        forces=np.array([t.forces for t in trace.terms]).reshape(len(trace.terms), roll.k),
        lp_status=tuple(lp.status for lp in trace.lps),
        lp_reason=tuple(lp.reason for lp in trace.lps),
        energy=roll.energy(trace),
        start_energy=start_energy,
        iterations=iterations,
        accepted=accepted,
        serpentine_group=group,
        relocation_targets={i: roll.model.nodes[n].copy() for i, n in roll.targets.items()},
    )


def plan_local(
    state: TransportState,
    params: TransportParams,
    rng: np.random.Generator,
    previous: LocalPlan | None = None,
    shift: int = 1,
    lp: ContactForceLP | None = None,
    scans: dict | None = None,
) -> LocalPlan:
    """One local plan from the current (filtered) state with ``params.strategy``.

    ``previous``: the last plan; its matrix shifted by ``shift`` intervals (the intervals
    elapsed since) starts the annealer. ``lp``: a :class:`ContactForceLP` to reuse (keeps its
    osqp workspace and warm start); ``scans``: a dict caching relocation scans across calls
    (:class:`TransportPlanner` keeps both). Never raises for an infeasible situation: the LP
    statuses and the energy say what is wrong; ``status`` is "at_subgoal" when the object
    already sits on the subgoal (nothing is optimised then; robots in contact follow).
    """
    if not state.robots:
        raise ValueError("state.robots: expected at least one robot")
    roll = Rollout(state, params, lp, scans)
    if not np.any(roll.carrot_twist(roll.start)):
        row = [IDLE if r.contact is None else FOLLOW for r in state.robots]
        trace = roll.run(np.tile(np.array(row, np.int64), (params.intervals, 1)))
        return make_plan(roll, trace, roll.energy(trace), "at_subgoal")
    return local_strategy(params.strategy).plan(roll, state, params, rng, previous, shift)


#: a local planner: (roll, state, params, rng, previous, shift) -> LocalPlan
LocalPlanner = Callable[
    [Rollout, TransportState, TransportParams, np.random.Generator, "LocalPlan | None", int],
    LocalPlan,
]


def _plan_serpentine(
    roll: Rollout,
    state: TransportState,
    params: TransportParams,
    rng: np.random.Generator,
    previous: LocalPlan | None,
    shift: int,
) -> LocalPlan:
    """``serpentine``: Sharma's two groups (:mod:`controller.planning.serpentine`)."""
    trace, group = serpentine(roll, state.serpentine_group)
    e = roll.energy(trace)
    plan = make_plan(roll, trace, e, "ok", group=group)
    groups = serpentine_groups(roll)
    return dataclasses.replace(plan, serpentine_groups=len({int(g) for g in groups if g >= 0}))


def _annealer(downhill: bool) -> LocalPlanner:
    """``sa``, or ``downhill`` (only ΔE <= 0 accepted): annealing over the action matrix."""

    def plan(
        roll: Rollout,
        state: TransportState,
        params: TransportParams,
        rng: np.random.Generator,
        previous: LocalPlan | None,
        shift: int,
    ) -> LocalPlan:
        start = roll.run(initial_matrix(roll, rng, previous, shift))
        if previous is not None and params.initial_actions == "lp":
            # the previous plan shifted, or the least-force pushing set now: the better start
            fresh = roll.run(lp_matrix(roll, params.intervals))
            if roll.energy(fresh).total < roll.energy(start).total:
                start = fresh
        best, accepted = anneal(roll, start, params, rng, downhill=downhill)
        return make_plan(roll, best, roll.energy(start), "ok", params.iterations, accepted)

    return plan


@dataclass(frozen=True)
class LocalStrategy:
    """A ``transport.strategy``: its planner and what the rest of the transport asks of it
    (the annealer's warm start, the mission's followers, the arrangement), so no call site
    compares names."""

    name: str
    plan: LocalPlanner
    # its plan's action matrix may start the next annealing (shifted by the intervals elapsed)
    warm_starts: bool
    # a FOLLOW robot keeps its contact with zero force, moving with the measured object
    # (Sharma §4.3); else it follows the plan's velocity like every attached robot
    passive_followers: bool
    # the pushing set: Eq. 5 for every robot, alone (Sharma §4.1); else Eq. 5 confirmed by
    # the contact-force LP, or the LP's least-force set (``planning.arrangement``)
    eq5_alone: bool
    # its plans say which of Sharma's two groups push (the run counts them and their switches)
    groups: bool = False


#: ``transport.strategy`` name -> its strategy. The valid names are
#: ``controller.config.TRANSPORT_STRATEGIES`` (checked at config load; tests/unit/test_config.py
#: checks both name the same strategies).
LOCAL_STRATEGIES = {
    s.name: s
    for s in (
        LocalStrategy("sa", _annealer(downhill=False), True, False, False),
        LocalStrategy("downhill", _annealer(downhill=True), True, False, False),
        LocalStrategy("serpentine", _plan_serpentine, False, True, True, groups=True),
    )
}
#: name -> planner (as before the registry)
LOCAL_PLANNERS = {name: s.plan for name, s in LOCAL_STRATEGIES.items()}


def local_strategy(name: str) -> LocalStrategy:
    """The registered strategy ``name`` (a ValueError naming the known ones)."""
    try:
        return LOCAL_STRATEGIES[name]
    except KeyError:
        known = ", ".join(sorted(LOCAL_STRATEGIES))
        raise ValueError(f"unknown transport strategy {name!r}; expected one of {known}") from None


class TransportPlanner:
    """What one mission's local planning keeps from tick to tick: the LP's osqp workspace,
    the relocation scans, the previous plan (warm start) and the serpentine group.

    ``plan(state, rng, elapsed)``: ``elapsed`` seconds since the previous plan decide how far
    its matrix is shifted (whole intervals). ``reset()`` forgets the previous plan and the
    serpentine group (call it when the subgoal changes or the robots re-arrange).
    """

    def __init__(self, params: TransportParams):
        self.params = params
        self.lp: ContactForceLP | None = None
        self.scans: dict = {}
        self.previous: LocalPlan | None = None

    def reset(self) -> None:
        self.previous = None
        self.scans.clear()

    def plan(
        self, state: TransportState, rng: np.random.Generator, elapsed: float = 0.0
    ) -> LocalPlan:
        if self.previous is not None and state.serpentine_group is None:
            state = dataclasses.replace(state, serpentine_group=self.previous.serpentine_group)
        dt = self.params.interval if self.previous is None else self.previous.interval
        shift = int(math.floor(elapsed / dt + 1e-9))
        k = len(state.robots)
        friction = state.model.contact_friction > 0
        if self.lp is None or self.lp.n_max < k or self.lp.friction != friction:
            self.lp = ContactForceLP(max(k, 1), friction=friction)
        plan = plan_local(state, self.params, rng, self.previous, shift, self.lp, self.scans)
        self.previous = plan
        return plan
