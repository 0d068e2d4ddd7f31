"""The fleet's filters stacked (``FleetEstimator.measure_robots``, ``estimation.batch``) give
what the per-track filterpy path gives, measurement by measurement: the same statuses, states
and covariances, for a mixed fleet with outliers, dropouts, bursts, out-of-order and garbage
measurements, re-acquisitions and commands of every kind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.config import EstimationSection
from controller.estimation import batch
from controller.estimation.fleet import FleetEstimator
from controller.estimation.models import motion, process_noise

TICK = 0.05
KINDS = ("omni", "diff", "omni", "diff", "omni", "omni", "diff")


def _fleet() -> FleetEstimator:
    return FleetEstimator(
        [(f"r{i}", k) for i, k in enumerate(KINDS)], EstimationSection(filter="ekf"), 1.0
    )


def _tick_poses(rng: np.random.Generator, t: float, truth: np.ndarray) -> list[tuple]:
    """One tick's poses, shuffled across robots, each robot's own in stamp order: 0 to 3 per
    robot (a dropout, a burst), with noise, outliers, stale stamps and garbage."""
    items = []
    for i in range(len(KINDS)):
        n = int(rng.choice([0, 1, 1, 2, 3], p=[0.1, 0.4, 0.2, 0.2, 0.1]))
        stamps = np.sort(t - TICK + TICK * rng.random(n))
        for s in stamps:
            z = truth[i] + rng.normal(0, [0.005, 0.005, 0.01])
            roll = rng.random()
            if roll < 0.05:
                z = z + [0.8, -0.5, 1.0]  # an outlier (a run of them re-acquires)
            elif roll < 0.07:
                s = s - 1.0  # older than the timeline: out of order
            elif roll < 0.08:
                z = [math.nan, 0.0, 0.0]  # garbage
            items.append((f"r{i}", float(s), *map(float, z)))
    order = rng.permutation(len(items))
    by_robot: dict[str, list] = {}
    for k in order:  # shuffled across robots, each robot's own order kept
        by_robot.setdefault(items[k][0], []).append(items[k])
    out, queues = [], {r: sorted(v, key=lambda it: it[1]) for r, v in by_robot.items()}
    for k in order:
        out.append(queues[items[k][0]].pop(0))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stacked_filters_match_the_per_track_filters(seed: int) -> None:
    rng = np.random.default_rng(seed)
    one, many = _fleet(), _fleet()
    truth = np.zeros((len(KINDS), 3))
    truth[:, 0] = np.arange(len(KINDS))
    vel = np.zeros((len(KINDS), 3))
    statuses = set()
    for k in range(1, 200):
        t = k * TICK
        if k % 7 == 1:  # new commands now and then; some robots skip a few ticks of them
            vel = rng.uniform([-0.4, -0.3, -1.0], [0.4, 0.3, 1.0], (len(KINDS), 3))
        truth += vel * TICK
        items = _tick_poses(rng, t, truth)
        got = many.measure_robots(items)
        want = [one.measure_robot(*it) for it in items]
        assert got == want
        statuses |= set(got)
        for i, kind in enumerate(KINDS):
            if rng.random() < 0.8:
                u = vel[i] if kind == "omni" else (vel[i][0], 0.0, vel[i][2])
                for est in (one, many):
                    est.command(f"r{i}", t, *u)
        a, b = one.robot_arrays(t + 0.02), many.robot_arrays(t + 0.02)
        np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(a[1], b[1], rtol=0, atol=1e-9)
    assert statuses == {"initialized", "accepted", "rejected", "out_of_order"}
    for rid in one.ids:
        ta, tb = one._tracks[rid], many._tracks[rid]  # noqa: SLF001 - the filters themselves
        np.testing.assert_allclose(ta.P, tb.P, rtol=1e-7, atol=1e-12)
        ea, eb = one.robot_estimate(rid, 10.0), many.robot_estimate(rid, 10.0)
        assert (ea.accepted, ea.rejected, ea.reacquired, ea.out_of_order) == (
            eb.accepted,
            eb.rejected,
            eb.reacquired,
            eb.out_of_order,
        )
        assert (ea.robot_id, ea.t, ea.stale) == (eb.robot_id, eb.t, eb.stale)
        assert ea.x == pytest.approx(eb.x, abs=1e-9)


@pytest.mark.parametrize("model", ["omni", "diff"])
def test_stacked_motion_and_noise_match_the_scalar_models(model: str) -> None:
    rng = np.random.default_rng(7)
    n = 6 if model == "omni" else 5
    X = rng.normal(0, 1, (9, n))
    dt = np.array([0.001, 0.02, 0.05, 0.0501, 0.11, 0.3, 1.7, 0.05, 0.049])
    U = rng.normal(0, 0.5, (9, 3 if model == "omni" else 2))
    S, F = batch.robot_motion_rows(model == "omni", X, dt, U, 0.15)
    Q = batch.process_noise_rows(model, X[:, 2], dt, 0.3, 0.7)
    for i in range(len(dt)):
        s1, f1 = motion(model, X[i], dt[i], U[i], 0.15)
        np.testing.assert_allclose(S[i], s1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(F[i], f1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Q[i], process_noise(model, X[i, 2], dt[i], 0.3, 0.7))


def test_unknown_robot_raises_before_anything_is_filtered() -> None:
    est = _fleet()
    with pytest.raises(KeyError):
        est.measure_robots([("r0", 0.0, 0.0, 0.0, 0.0), ("nope", 0.0, 0.0, 0.0, 0.0)])
    assert est.robot_estimate("r0", 0.0).initialized is False
