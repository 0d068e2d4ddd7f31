"""Benchmark of the pose filters (issue 6). Prints one JSON object on stdout.

* ``step_us``: microseconds per predict+gate+update of one robot, EKF/UKF x omni/diff (median
  of repeats over a 12 s jittered 20-50 Hz track), against a baseline run in the same process:
  filterpy's linear ``KalmanFilter`` (6-state constant velocity, no angles, no gating).
* ``tick_ms``: milliseconds per 20 Hz control tick for 50 robots (25 omni, 25 diff): 50
  commands, the measurements that arrived since the last tick, ``robot_arrays`` and 50
  ``robot_estimate`` calls, all predicted to the tick time.
* ``accuracy``: on the issue's scenario (sigma_xy 1 cm, sigma_theta 1 deg, 5 % outliers of
  0.5 m, 20-50 Hz): position RMSE over the raw inlier measurements' RMSE (at the stamps and at
  the ticks), over the raw RMSE with outliers, share of outliers / good measurements rejected,
  heading errors (also for a robot spinning through +-pi), and the object's 0.5 s prediction
  error on the sine path against holding the last measurement.

Usage: python bench/estimation.py [--repeats N] [--seeds N]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from filterpy.kalman import KalmanFilter  # noqa: E402

from controller.config import EstimationSection  # noqa: E402
from controller.estimation.fleet import FleetEstimator  # noqa: E402
from controller.estimation.track import TrackFilter  # noqa: E402
from tests.support.estimation_tracks import rmse, run_robot, simulate_robot, sine_object  # noqa: E402

TICK = 0.05


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def time_track(track, make) -> float:
    """Seconds per measurement for feeding a whole track through a fresh filter."""
    f = make()
    cmd_i = 0
    t0 = time.perf_counter()
    for m, t in enumerate(track.t_meas):
        while cmd_i < len(track.t_cmd) and track.t_cmd[cmd_i] <= t:
            f.command(track.t_cmd[cmd_i], track.cmd[cmd_i])
            cmd_i += 1
        f.measure(t, track.z[m])
    return (time.perf_counter() - t0) / len(track.t_meas)


class _Baseline:
    """filterpy's linear KalmanFilter, 6-state constant velocity: the cost floor."""

    def __init__(self) -> None:
        kf = KalmanFilter(dim_x=6, dim_z=3)
        kf.H = np.hstack([np.eye(3), np.zeros((3, 3))])
        kf.R = np.diag([1e-4, 1e-4, 3e-4])
        kf.P = np.eye(6)
        self.kf = kf
        self.t = None

    def command(self, t: float, u: np.ndarray) -> None:
        pass

    def measure(self, t: float, z: np.ndarray) -> None:
        if self.t is None:
            self.kf.x = np.r_[z, np.zeros(3)].reshape(-1, 1)
            self.t = t
            return
        dt = t - self.t
        self.t = t
        F = np.eye(6)
        F[0, 3] = F[1, 4] = F[2, 5] = dt
        self.kf.F = F
        self.kf.Q = np.eye(6) * 1e-3 * dt
        self.kf.predict()
        self.kf.update(z.reshape(-1, 1))


def bench_steps(repeats: int) -> dict:
    """Repeats are interleaved across the models so machine noise hits them alike."""
    tracks = {k: simulate_robot(k, np.random.default_rng(1)) for k in ("omni", "diff")}
    makers = {"baseline_linear_kf": ("omni", _Baseline)}
    for filt in ("ekf", "ukf"):
        p = EstimationSection(filter=filt)
        for kind in ("omni", "diff"):

            def make(kind=kind, p=p, filt=filt):
                f = TrackFilter(kind, filt, p, p.process_accel**2, p.process_yaw_accel**2)
                return _CmdAdapter(f, kind)

            makers[f"{filt}_{kind}"] = (kind, make)
    times: dict[str, list[float]] = {name: [] for name in makers}
    for r in range(repeats):
        for name, (kind, make) in makers.items():
            times[name].append(time_track(tracks[kind], make))
        progress(f"step repeat {r + 1}/{repeats}")
    out: dict = {}
    base = statistics.median(times["baseline_linear_kf"]) * 1e6
    out["baseline_linear_kf"] = round(base, 1)
    for name in makers:
        if name != "baseline_linear_kf":
            us = statistics.median(times[name]) * 1e6
            out[name] = round(us, 1)
            out[f"{name}_over_baseline"] = round(us / base, 2)
    return out


class _CmdAdapter:
    def __init__(self, f: TrackFilter, kind: str):
        self.f, self.kind = f, kind

    def command(self, t: float, u: np.ndarray) -> None:
        self.f.command(t, u if self.kind == "omni" else (u[0], u[2]))

    def measure(self, t: float, z: np.ndarray) -> None:
        self.f.measure(t, z)


def bench_ticks(n_robots: int = 50, duration: float = 4.0, repeats: int = 3) -> dict:
    out: dict = {}
    kinds = ["omni" if i % 2 == 0 else "diff" for i in range(n_robots)]
    rng = np.random.default_rng(2)
    tracks = [simulate_robot(k, rng, duration=duration, dt=2e-3) for k in kinds]
    ids = [f"r{i}" for i in range(n_robots)]
    per_tick: dict[str, list[float]] = {"ekf": [], "ukf": []}
    for _ in range(repeats):
        for filt in ("ekf", "ukf"):
            est = FleetEstimator(
                list(zip(ids, kinds, strict=True)), EstimationSection(filter=filt), 0.3
            )
            nxt = [0] * n_robots
            for j, now in enumerate(np.arange(0.0, duration, TICK)):
                t0 = time.perf_counter()
                for i, tr in enumerate(tracks):
                    m = nxt[i]
                    while m < len(tr.t_meas) and tr.t_arrive[m] <= now:
                        est.measure_robot(ids[i], tr.t_meas[m], *tr.z[m])
                        m += 1
                    nxt[i] = m
                est.robot_arrays(now)
                for i, rid in enumerate(ids):
                    est.robot_estimate(rid, now)
                    k = min(int(now / TICK), len(tracks[i].cmd) - 1)
                    est.command(rid, now, *tracks[i].cmd[k])
                if j >= 20:  # after every track is initialised
                    per_tick[filt].append(time.perf_counter() - t0)
    for filt, ts in per_tick.items():
        out[f"{filt}_{n_robots}_robots"] = round(statistics.median(ts) * 1e3, 2)
        out[f"{filt}_{n_robots}_robots_p95"] = round(float(np.percentile(ts, 95)) * 1e3, 2)
        progress(f"tick {filt}: {out[f'{filt}_{n_robots}_robots']} ms")
    out["measurements_per_robot_per_tick"] = round(
        float(np.mean([len(tr.t_meas) for tr in tracks])) / (duration / TICK), 2
    )
    return out


def bench_accuracy(seeds: int) -> dict:
    out: dict = {}
    for filt in ("ekf", "ukf"):
        p = EstimationSection(filter=filt)
        for kind in ("omni", "diff"):
            ratios, tick_ratios, all_ratios, out_rej, good_rej, head = [], [], [], [], [], []
            for s in range(seeds):
                tr = simulate_robot(kind, np.random.default_rng(100 + s))
                r = run_robot(tr, p)
                ratios.append(r.ratio())
                tick_ratios.append(r.tick_ratio())
                all_ratios.append(rmse(r.post_err[20:]) / rmse(r.raw_err[20:]))
                out_rej.append(r.outliers_rejected())
                good_rej.append(r.good_rejected())
                head.append(math.degrees(float(r.post_head_err[20:].max())))
            spin = run_robot(
                simulate_robot(kind, np.random.default_rng(7), duration=10, spin=2.5), p
            )
            out[f"{filt}_{kind}"] = {
                "rmse_ratio_vs_inlier_measurements": round(max(ratios), 3),
                "rmse_ratio_at_ticks": round(max(tick_ratios), 3),
                "rmse_ratio_vs_all_measurements": round(max(all_ratios), 3),
                "outliers_rejected": round(min(out_rej), 4),
                "good_rejected": round(max(good_rej), 4),
                "heading_max_err_deg": round(max(head), 2),
                "spin_heading_max_err_deg": round(
                    math.degrees(float(spin.post_head_err[20:].max())), 2
                ),
                "spin_rmse_ratio": round(spin.ratio(), 3),
            }
            progress(f"accuracy {filt} {kind}: {out[f'{filt}_{kind}']}")
        out[f"{filt}_object_sine_0.5s"] = object_prediction(p)
    out["seeds"] = seeds
    out["worst_case_over_seeds"] = True
    return out


def object_prediction(p: EstimationSection) -> dict:
    tr = sine_object(np.random.default_rng(21), duration=30.0)
    est = FleetEstimator([], p, 0.3)
    pred, hold, hold_in = [], [], []
    m = 0
    last_in = tr.z[0]
    for now in np.arange(0.0, 30.0, TICK):
        while m < len(tr.t_meas) and tr.t_meas[m] <= now:
            est.measure_object(tr.t_meas[m], *tr.z[m])
            if not tr.outlier[m]:
                last_in = tr.z[m]
            m += 1
        if now < 2.0:
            continue
        fut = tr.truth_at(now + 0.5)[0]
        e = est.predict_object(now, 0.5)
        pred.append(math.hypot(e.x - fut[0], e.y - fut[1]))
        hold.append(float(np.hypot(*(tr.z[m - 1, :2] - fut[:2]))))
        hold_in.append(float(np.hypot(*(last_in[:2] - fut[:2]))))
    return {
        "prediction_rmse_m": round(rmse(np.array(pred)), 4),
        "hold_last_rmse_m": round(rmse(np.array(hold)), 4),
        "hold_last_inlier_rmse_m": round(rmse(np.array(hold_in)), 4),
        "ratio": round(rmse(np.array(pred)) / rmse(np.array(hold)), 3),
        "ratio_vs_inlier_hold": round(rmse(np.array(pred)) / rmse(np.array(hold_in)), 3),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    result = {
        "step_us": bench_steps(args.repeats),
        "tick_ms": bench_ticks(repeats=max(1, args.repeats // 2)),
        "accuracy": bench_accuracy(args.seeds),
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
