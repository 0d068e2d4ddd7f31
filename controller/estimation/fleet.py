"""``FleetEstimator``: one filter per robot plus one for the object, the runtime's view.

Answers queries at a control tick by extrapolating copies (latency compensation); logs only
on changes (a track starts or stops rejecting, re-acquires, turns stale or fresh).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from controller.config import EstimationSection
from controller.estimation import batch
from controller.estimation.models import ROBOT_MODELS, THETA, world_velocity
from controller.estimation.track import STATUS_OUT_OF_ORDER, STATUS_REJECTED, TrackFilter

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RobotEstimate:
    """A robot's filtered state at time ``t`` (s): pose (m, m, rad), world velocities (m/s,
    m/s, rad/s), 1-sigma uncertainties (sigma_xy: largest axis of the position ellipse, m;
    sigma_theta: rad), and the filter's bookkeeping. Before the first measurement the pose and
    velocities are NaN, the sigmas inf, ``initialized`` False and ``stale`` True."""

    robot_id: str
    t: float
    x: float
    y: float
    theta: float
    vx: float
    vy: float
    wz: float
    sigma_xy: float
    sigma_theta: float
    stale: bool
    rejected: int
    out_of_order: int
    initialized: bool
    accepted: int = 0
    reacquired: int = 0


@dataclass(frozen=True)
class ObjectEstimate:
    """The object's filtered state at ``t`` (s); fields as in :class:`RobotEstimate`."""

    t: float
    x: float
    y: float
    theta: float
    vx: float
    vy: float
    wz: float
    sigma_xy: float
    sigma_theta: float
    stale: bool
    arrested: bool
    rejected: int
    out_of_order: int
    initialized: bool
    accepted: int = 0
    reacquired: int = 0


def _sigmas(P: FloatArray) -> tuple[float, float]:
    pxy = P[:2, :2]
    tr = 0.5 * (pxy[0, 0] + pxy[1, 1])
    det = pxy[0, 0] * pxy[1, 1] - pxy[0, 1] * pxy[1, 0]
    lam = tr + math.sqrt(max(tr * tr - det, 0.0))
    return math.sqrt(max(lam, 0.0)), math.sqrt(max(P[THETA, THETA], 0.0))


_NAN_STATE = (math.nan,) * 6


class FleetEstimator:
    """One filter per robot plus one for the object; the runtime's view of the world.

    Args:
        robots: (robot_id, kind) pairs, kind "omni" or "diff"; the order of ``robot_arrays``.
        params: the ``[estimation]`` config section.
        stale_after: seconds without an accepted measurement before a track is stale
            (``fleet.stale_after``).
    """

    def __init__(
        self,
        robots: Sequence[tuple[str, str]],
        params: EstimationSection,
        stale_after: float,
    ):
        if not stale_after > 0:
            raise ValueError(f"stale_after must be > 0 s, got {stale_after!r}")
        self.params = params
        self.stale_after = float(stale_after)
        self.ids: tuple[str, ...] = tuple(rid for rid, _ in robots)
        self._tracks: dict[str, TrackFilter] = {}
        for rid, kind in robots:
            if kind not in ROBOT_MODELS:
                raise ValueError(f"robot {rid!r}: unknown kind {kind!r}; expected {ROBOT_MODELS}")
            if rid in self._tracks:
                raise ValueError(f"robot {rid!r} listed twice")
            self._tracks[rid] = TrackFilter(
                kind, params.filter, params, params.process_accel**2, params.process_yaw_accel**2
            )
        self._object = self._make_object_track(arrested=False)
        self._arrested = False
        self._was_rejecting: dict[str, bool] = {}
        self._was_stale: dict[str, bool] = {}

    def _make_object_track(self, arrested: bool) -> TrackFilter:
        p = self.params
        acc = p.object_arrested_accel if arrested else p.object_process_accel
        # Yaw noise scaled like the linear one relative to the robots' ratio.
        yaw = acc * p.process_yaw_accel / p.process_accel
        return TrackFilter("object", p.filter, p, acc**2, yaw**2)

    def _track(self, robot_id: str) -> TrackFilter:
        try:
            return self._tracks[robot_id]
        except KeyError:
            raise KeyError(f"unknown robot id {robot_id!r}; known: {list(self.ids)}") from None

    # ---- inputs

    def command(self, robot_id: str, t: float, vx: float, vy: float, wz: float) -> None:
        """Record the body-frame command (m/s, m/s, rad/s) sent to a robot at t (s).

        A differential robot's vy is ignored (it cannot move sideways).
        """
        tr = self._track(robot_id)
        u = (vx, vy, wz) if tr.model == "omni" else (vx, wz)
        try:
            tr.command(t, u)
        except ValueError as e:
            raise ValueError(f"robot {robot_id!r}: {e}") from None

    def measure_robot(self, robot_id: str, t: float, x: float, y: float, theta: float) -> str:
        """Feed a robot's pose measurement (m, m, rad) stamped t (s).

        Returns "accepted", "rejected", "out_of_order" or "initialized".
        """
        tr = self._track(robot_id)
        status = tr.measure(t, (x, y, theta))
        self._note_gate(robot_id, tr, status)
        return status

    def measure_robots(self, items: Sequence[tuple[str, float, float, float, float]]) -> list[str]:
        """Feed many robots' pose measurements, ``(robot_id, t, x, y, theta)`` each; returns
        their statuses in order. Each robot's measurements are taken in the order given, as by
        ``measure_robot``; the EKF's predict, gate and update run for all robots of one model
        at once (``estimation.batch``): a round per measurement a robot has in ``items``."""
        out = [""] * len(items)
        rounds: list[list[int]] = []
        seen: dict[str, int] = {}
        for k, (rid, *_rest) in enumerate(items):
            self._track(rid)  # an unknown id raises as measure_robot does
            r = seen.get(rid, 0)
            seen[rid] = r + 1
            if r == len(rounds):
                rounds.append([])
            rounds[r].append(k)
        for ks in rounds:
            pending: dict[tuple, list[tuple[int, TrackFilter, float, FloatArray]]] = {}
            for k in ks:
                rid, t, x, y, theta = items[k]
                tr = self._tracks[rid]
                if not tr.strategy.stacks:
                    out[k] = tr.measure(t, (x, y, theta))
                    continue
                zv, status = tr.admit(t, (x, y, theta))
                if status is None:
                    pending.setdefault(_stack_key(tr), []).append((k, tr, t, zv))
                else:
                    out[k] = status
            for key, rows in pending.items():
                if len(rows) >= STACK_MIN:
                    self._filter_rows(key[0], rows, out)
                    continue
                for k, tr, t, zv in rows:  # a few: one by one costs less than the stacking
                    out[k] = tr.filter(t, zv)
            for k in ks:
                self._note_gate(items[k][0], self._tracks[items[k][0]], out[k])
        return out

    def _filter_rows(
        self, model: str, rows: list[tuple[int, TrackFilter, float, FloatArray]], out: list[str]
    ) -> None:
        """Predict, gate and update one model's tracks to their measurements, stacked."""
        trs = [tr for _, tr, _, _ in rows]
        X, P = _predict_stack(model, trs, [t for _, _, t, _ in rows])
        Z = np.stack([zv for _, _, _, zv in rows])
        for i, (_, tr, t, _) in enumerate(rows):
            tr.strategy.set_state(tr.kf, X[i], P[i])
            tr.t = t
        try:
            d2 = batch.gate_rows(X, P, Z, trs[0].R)
            X1, P1 = batch.update_rows(X, P, Z, trs[0].R)
        except np.linalg.LinAlgError:  # one S singular: each on its own (that one restarts)
            for k, tr, t, zv in rows:
                out[k] = tr.judge(t, zv)
            return
        for i, (k, tr, t, zv) in enumerate(rows):
            out[k] = tr.conclude(t, zv, float(d2[i]), (X1[i], P1[i]))

    def measure_object(self, t: float, x: float, y: float, theta: float) -> str:
        """Feed the object's pose measurement (m, m, rad) stamped t (s); returns a status."""
        status = self._object.measure(t, (x, y, theta))
        self._note_gate("object", self._object, status)
        return status

    def set_object_arrested(self, arrested: bool) -> None:
        """Switch the object's model between live and arrested (keeps its state; see the
        module docstring). Releasing it forgets the push reports."""
        arrested = bool(arrested)
        if arrested == self._arrested:
            return
        p = self.params
        acc = p.object_arrested_accel if arrested else p.object_process_accel
        self._object.q_lin = acc**2
        self._object.q_yaw = (acc * p.process_yaw_accel / p.process_accel) ** 2
        if not arrested:
            self._object.clear_commands()
        self._object._version += 1
        self._arrested = arrested
        log.info("object filter: %s model", "arrested" if arrested else "live")

    def push_object(self, t: float, vx: float, vy: float, wz: float) -> None:
        """Optional: the world-frame push velocity (m/s, m/s, rad/s) commanded for the arrested
        object from time t (s) on. Ignored while the object is not arrested."""
        if self._arrested:
            self._object.command(t, (vx, vy, wz))

    # ---- outputs

    def robot_estimate(self, robot_id: str, now: float) -> RobotEstimate:
        """A robot's estimate predicted to ``now`` (s) without moving its filter's timeline."""
        tr = self._track(robot_id)
        stale = tr.stale(now, self.stale_after)
        self._note_stale(robot_id, stale)
        if not tr.initialized:
            return RobotEstimate(
                robot_id, now, *_NAN_STATE, math.inf, math.inf, True, 0, tr.out_of_order, False
            )
        x, P = tr.state_at(now)
        v = world_velocity(tr.model, x)
        sxy, sth = _sigmas(P)
        return RobotEstimate(
            robot_id,
            max(now, tr.t or now),
            float(x[0]),
            float(x[1]),
            float(x[2]),
            float(v[0]),
            float(v[1]),
            float(v[2]),
            sxy,
            sth,
            stale,
            tr.rejected,
            tr.out_of_order,
            True,
            tr.accepted,
            tr.reacquired,
        )

    def robot_arrays(self, now: float) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Fleet state at ``now`` (s) in construction order: (N,3) poses (x, y, theta), (N,3)
        world velocities (vx, vy, wz) and an (N,) stale mask. Uninitialised robots are NaN."""
        n = len(self.ids)
        poses = np.full((n, 3), np.nan)
        vels = np.full((n, 3), np.nan)
        stale = np.ones(n, dtype=bool)
        self._extrapolate(now)
        for i, rid in enumerate(self.ids):
            tr = self._tracks[rid]
            stale[i] = tr.stale(now, self.stale_after)
            self._note_stale(rid, bool(stale[i]))
            if tr.initialized:
                x, _ = tr.state_at(now)
                poses[i] = x[:3]
                vels[i] = world_velocity(tr.model, x)
        return poses, vels, stale

    def _extrapolate(self, now: float) -> None:
        """Every stacking robot track's state at ``now``, extrapolated per model at once
        (``estimation.batch``) and cached in its track, where ``state_at`` finds it."""
        groups: dict[tuple, list[TrackFilter]] = {}
        for tr in self._tracks.values():
            if tr.strategy.stacks and tr.initialized and tr.t < now and not tr.is_cached(now):
                groups.setdefault(_stack_key(tr), []).append(tr)
        for key, trs in groups.items():
            if len(trs) < STACK_MIN:
                continue  # a few: state_at one by one costs less than the stacking
            X, P = _predict_stack(key[0], trs, [now] * len(trs))
            for i, tr in enumerate(trs):
                tr.keep(now, X[i], P[i])

    def object_estimate(self, now: float) -> ObjectEstimate:
        """The object's estimate predicted to ``now`` (s)."""
        return self._object_at(now, now)

    def predict_object(self, now: float, horizon: float) -> ObjectEstimate:
        """The object's pose predicted ``horizon`` seconds after ``now`` (constant velocity);
        ``stale`` is judged at ``now``."""
        return self._object_at(now, now + max(0.0, horizon))

    def _object_at(self, now: float, at: float) -> ObjectEstimate:
        tr = self._object
        stale = tr.stale(now, self.stale_after)
        self._note_stale("object", stale)
        if not tr.initialized:
            return ObjectEstimate(
                at,
                *_NAN_STATE,
                math.inf,
                math.inf,
                True,
                self._arrested,
                0,
                tr.out_of_order,
                False,
            )
        x, P = tr.state_at(at)
        sxy, sth = _sigmas(P)
        return ObjectEstimate(
            max(at, tr.t or at),
            *(float(v) for v in x[:6]),
            sxy,
            sth,
            stale,
            self._arrested,
            tr.rejected,
            tr.out_of_order,
            True,
            tr.accepted,
            tr.reacquired,
        )

    # ---- change logging (never per tick)

    def _note_gate(self, name: str, tr: TrackFilter, status: str) -> None:
        """The gate's rejections, logged by what they mean. An isolated outlier is only
        counted; ``REJECT_EPISODE`` in a row (a bump at contact, a robot moved) and the
        re-acquisition that follows are normal operation: INFO. ``REJECT_WARN`` in a row that
        never agree (no re-acquisition: noise, a second marker, a spoofer) are a problem: one
        WARNING per episode."""
        if status == STATUS_OUT_OF_ORDER:
            return
        n = tr.consecutive_rejected
        rejecting = status == STATUS_REJECTED and n >= REJECT_EPISODE
        was = self._was_rejecting.get(name, False)
        if tr.just_reacquired:
            log.info(
                "%s: re-acquired after %d consistent rejected measurements (d2=%.1f)",
                name,
                self.params.reacquire_after,
                tr.last_d2,
            )
            self._was_rejecting[name] = False
            return
        if rejecting and not was:
            log.info(
                "%s: %d measurements in a row rejected by the gate (d2=%.1f > %.1f), %d so far",
                name,
                n,
                tr.last_d2,
                tr.threshold,
                tr.rejected,
            )
        elif rejecting and n == max(REJECT_WARN, self.params.reacquire_after + 1):
            log.warning(
                "%s: %d measurements in a row rejected by the gate and they do not agree "
                "(d2=%.1f > %.1f): its estimate runs on the prediction alone",
                name,
                n,
                tr.last_d2,
                tr.threshold,
            )
        elif was and not rejecting:
            log.info("%s: measurements accepted again (%d rejected so far)", name, tr.rejected)
        self._was_rejecting[name] = rejecting

    def _note_stale(self, name: str, stale: bool) -> None:
        was = self._was_stale.get(name)
        if was is None:
            self._was_stale[name] = stale
            return
        if stale != was:
            if stale:
                log.warning(
                    "%s: pose stale (no accepted measurement for %.2f s)", name, self.stale_after
                )
            else:
                log.info("%s: pose fresh", name)
            self._was_stale[name] = stale


def _stack_key(tr: TrackFilter) -> tuple:
    """What tracks stacked together share: the model and its noise and lag."""
    return (tr.model, tr.tau, tr.q_lin, tr.q_yaw)


def _predict_stack(
    model: str, trs: list[TrackFilter], ts: list[float]
) -> tuple[FloatArray, FloatArray]:
    """The tracks' states and covariances predicted to their times ``ts``, stacked."""
    first = trs[0]
    return batch.predict_rows(
        model,
        np.stack([tr.x for tr in trs]),
        np.stack([tr.P for tr in trs]),
        [tr.segments(tr.t, t) for tr, t in zip(trs, ts, strict=True)],  # type: ignore[arg-type]
        first.tau,
        first.q_lin,
        first.q_yaw,
    )


# robots of one model below which a round of poses (or the extrapolation to the tick) is
# filtered one robot at a time: numpy's per-call cost makes a stack of 1-3 slower than filterpy
# (2 robots with 15 poses a tick each: 11.4 ms stacked, 9.0 one by one; 6 robots with 2: 2.0
# against 3.7 ms; a long gap's many sub-steps on one robot: 3x slower stacked)
STACK_MIN = 4
REJECT_EPISODE = 3  # consecutive rejections logged as a rejection episode (isolated: counted)
# consecutive rejections that did not re-acquire the track (they disagree): a WARNING, once per
# episode (a third of a second of poses at 30 Hz; a consistent run re-acquires after
# estimation.reacquire_after, 5 by default)
REJECT_WARN = 10
