"""Which ways the fleet can push the object (issue 34, item 9): per direction of travel in the
object's frame, whether a set of contacts the robots can hold moves it, so that the route can
choose the object's heading along the way (a heavy crate turned to present its long face).

Pure: a config and arrays in, numbers out; no I/O, no clock, no randomness.

**What can push** (:meth:`PushDirections.capacity`): the set of contacts the transport would
ask for along that direction (``controller.planning.arrangement.wrench_set``: the least-force
LP over every candidate node, reinforced up to every robot at the weakest robot's force, aiming
at ``margin`` times the floor friction's wrench), as the share of the floor friction's wrench it
produces. A direction can be pushed (:meth:`PushDirections.can_push`) when the sets of every
bucket within ``slack`` of it produce the whole wrench (the transport's own test), so that an
object whose heading is a turn's tolerance off the route's can still be pushed. The answers are
cached per bucket: 72 buckets of 5° cover every pair of the route's 8 directions and 36
headings.

**What no set can push** (:meth:`PushDirections.bound`): an upper bound, the LP over every
candidate contact at once (at most one robot in any stretch of a face shorter than a robot's
diameter: two robots do not overlap; at most ``robots`` times the weakest force in all;
contact friction cones of ``object.contact_friction``) maximising the share of the floor
friction's wrench it produces. Below 1 in every direction, no heading and no set of the whole
fleet can move the object: that is the proof a ``too_heavy`` failure cites.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

from controller.config import FleetConfig
from controller.planning.contact_lp import required_wrench

FloatArray = NDArray[np.float64]
BUCKETS = 72  # 5° buckets: every object-frame angle of 8 directions at 36 headings
SLACK = math.radians(10.0)  # a turn counts as done 8° short (transport's subgoal_heading)


@dataclass(eq=False)
class PushDirections:
    """Per object-frame direction of travel, whether the fleet can push the object that way
    (see the module docstring). ``robots``: how many may push; ``weakest`` (N): the force of
    the weakest; ``margin``: the share of the floor friction a set must produce (the
    transport's ``turn_margin``)."""

    cfg: FleetConfig
    model: object  # transport_model.ObjectModel
    robots: int
    weakest: float
    margin: float = 1.2  # arrangement.TURN_MARGIN
    slack: float = SLACK
    buckets: int = BUCKETS
    _cap: dict[int, tuple[float, int]] = field(default_factory=dict, repr=False)
    _bound: dict[int, float] = field(default_factory=dict, repr=False)
    _bound_lp: _BoundLP | None = field(default=None, repr=False)

    @classmethod
    def from_config(cls, cfg: FleetConfig, margin: float = 1.2) -> PushDirections:
        """For the config's object and whole fleet (its weakest robot's ``max_force``)."""
        from controller.planning.arrangement import planning_model

        model = planning_model(cfg)  # under the error model, the heaviest the object may be
        weakest = min(r.max_force for r in cfg.robots)
        return cls(cfg, model, len(cfg.robots), float(weakest), margin)

    @property
    def need(self) -> float:
        """N: the floor friction a push overcomes (μ·m·g)."""
        m = self.model
        return float(np.hypot(*required_wrench([1.0, 0.0, 0.0], m.mass, m.floor_friction, 1.0)[:2]))

    def _bucket(self, angle: float) -> int:
        return int(round(angle / (2 * math.pi) * self.buckets)) % self.buckets

    def _angle(self, b: int) -> float:
        return 2 * math.pi * b / self.buckets

    def _twist(self, b: int) -> FloatArray:
        a = self._angle(b)
        return np.array([math.cos(a), math.sin(a), 0.0])

    def capacity(self, angle: float) -> tuple[float, int]:
        """(share of the floor friction the set the transport would ask for produces, its
        robots) for travel along ``angle`` (rad, object frame), at its bucket."""
        from controller.planning.arrangement import wrench_set

        b = self._bucket(angle)
        if b not in self._cap:
            _, _, value, n = wrench_set(
                self.cfg, self.model, self._twist(b), self.weakest, self.robots, self.margin
            )
            self._cap[b] = (float(value) * self.margin, int(n))
        return self._cap[b]

    def can_push(self, angle: float) -> bool:
        """Whether the sets of every bucket within ``slack`` of ``angle`` overcome the floor
        friction (the object's heading may be that far off the route's when it is pushed)."""
        x = angle / (2 * math.pi) * self.buckets
        w = self.slack / (2 * math.pi) * self.buckets
        near = range(math.floor(x - w + 1e-9), math.ceil(x + w - 1e-9) + 1)
        return all(self.capacity(self._angle(b))[0] >= 1.0 - 1e-9 for b in near)

    @property
    def learned(self) -> int:
        """How many directions' sets have been computed so far (each an LP and its
        reinforcement)."""
        return len(self._cap)

    def pushable_angles(self) -> list[float]:
        """The buckets' angles (rad, object frame) the fleet can push the object along."""
        return [self._angle(b) for b in range(self.buckets) if self.can_push(self._angle(b))]

    def bound(self, angle: float) -> float:
        """Upper bound of the share of the floor friction any set of the fleet produces along
        ``angle`` (rad, object frame), at its bucket (see the module docstring)."""
        b = self._bucket(angle)
        if b not in self._bound:
            if self._bound_lp is None:
                self._bound_lp = _BoundLP(self.cfg, self.model, self.robots, self.weakest)
            self._bound[b] = self._bound_lp.share(self._twist(b))
        return self._bound[b]

    def best(self) -> tuple[float, float, int, float]:
        """Over every bucket: (the best set's share, its angle rad, its robots, the largest
        upper bound's share) — the figures a ``too_heavy`` failure cites."""
        caps = [self.capacity(self._angle(b)) for b in range(self.buckets)]
        i = int(np.argmax([c[0] for c in caps]))
        top = max(self.bound(self._angle(b)) for b in range(self.buckets))
        return caps[i][0], self._angle(i), caps[i][1], top

    def too_heavy_detail(self) -> str:
        """Why no route can be pushed: the force needed, the best set's share at its best
        direction, and the LP bound over every contact (a proof when it is under 100 %)."""
        from controller.planning.arrangement import error_note

        share, angle, n, top = self.best()
        text = (
            f"too heavy to push at any heading: the floor friction needs {self.need:.1f} N; the "
            f"best set of contacts ({n} robot{'s' * (n != 1)} where they fit, {self.weakest:g} N"
            f" each, pushing at {math.degrees(angle):.0f}° in the object's frame) reaches "
            f"{100 * share:.0f} % of it; the {self.robots} robots have "
            f"{self.robots * self.weakest:.1f} N in all"
        )
        if share >= 1.0:
            text += (
                f", but no direction keeps 100 % for headings {math.degrees(self.slack):.0f}° off"
                " it, as a turn short of its heading needs"
            )
        if top < 1.0:
            text += (
                f"; with every robot on every face where one fits, no set reaches more than "
                f"{100 * top:.0f} % (the LP over all candidate contacts)"
            )
        else:
            text += (
                f"; the LP over all candidate contacts allows up to {100 * top:.0f} % (it "
                "ignores how many robots fit where), more than any set the planner found"
            )
        return text + error_note(self.cfg)


class _BoundLP:
    """The LP of :meth:`PushDirections.bound` for one object and fleet: its contacts, their
    wrench blocks and the force-limit rows built once; :meth:`share` solves it for a twist
    (only the wrench column changes between directions)."""

    def __init__(self, cfg: FleetConfig, model, robots: int, fmax: float) -> None:
        from controller.planning.arrangement import candidates

        r = cfg.max_robot_radius
        cand = candidates(cfg)
        self.model = model
        pts, out = cand.points, cand.normals
        n = self.n = len(pts)
        rel = pts - model.centroid
        push = -out  # robots push inward
        tang = np.column_stack([-push[:, 1], push[:, 0]])

        def wrench(f: FloatArray) -> FloatArray:
            return np.vstack([f.T, rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]])

        mu = float(model.contact_friction)
        # variables: normal forces (n), tangential + and - (n each, only with friction), s
        blocks = [wrench(push)]
        if mu > 0:
            blocks += [wrench(tang), wrench(-tang)]
        nv = n * len(blocks)
        self.forces = np.hstack(blocks)
        rows, rhs = [], []
        total = np.zeros(nv + 1)
        total[:n] = 1.0
        rows.append(total)
        rhs.append(robots * fmax)
        # nodes of one edge are collinear, their robots' centres as far apart as the nodes: at
        # most one robot (one force limit) in every stretch of an edge shorter than a diameter
        along = np.einsum("jik,jk->ji", pts[None] - pts[:, None], tang)  # [j, i]: i ahead of j
        same = cand.edges[:, None] == cand.edges[None]
        window = same & (along >= -1e-12) & (along < 2 * r - 1e-9)
        for j in range(n):
            row = np.zeros(nv + 1)
            row[:n] = window[j]
            rows.append(row)
            rhs.append(fmax)
        if mu > 0:
            cone = np.zeros((n, nv + 1))
            cone[:, :n] = -mu * np.eye(n)
            cone[:, n : 2 * n] = np.eye(n)
            cone[:, 2 * n : 3 * n] = np.eye(n)
            rows.extend(cone)
            rhs.extend([0.0] * n)
        self.a_ub, self.b_ub = np.array(rows), np.array(rhs)
        self.c = np.zeros(nv + 1)
        self.c[-1] = -1.0
        self.bounds = [(0.0, fmax)] * n + [(0.0, None)] * (nv - n) + [(0.0, None)]

    def share(self, twist: FloatArray) -> float:
        """The largest s such that contacts at every candidate node produce s times the
        wrench ``twist`` needs; 0 when none produces it at all."""
        if self.n == 0:
            return 0.0
        m = self.model
        need = required_wrench(twist, m.mass, m.floor_friction, m.mean_radius)
        a_eq = np.hstack([self.forces, -need[:, None]])
        res = linprog(self.c, A_ub=self.a_ub, b_ub=self.b_ub, A_eq=a_eq, b_eq=np.zeros(3),
                      bounds=self.bounds, method="highs")  # fmt: skip
        if res.status != 0:
            return 0.0
        return float(res.x[-1])
