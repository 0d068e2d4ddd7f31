"""Why the serpentine stalls, from its traces (issue 34, item 2): prints ONE JSON object.

Each scenario of the varied suite (``bench/transport_loop.py``'s ``draw_varied_suite``, seed
3141, never tuned on) is run once with ``transport.strategy = "serpentine"`` (Sharma §4.1: Eq. 5
for every robot, the groups alternating on the deviation rule) in lockstep on pybullet, its MCAP
log kept; then the log is read back. Per run, over the local plans (``plan/transport``):

- ``first_lp_feasible``: plans whose first interval's contact-force LP has an answer (the
  model says the pushing group can move the object as planned);
- ``two_groups``: plans with both of Sharma's groups manned;
- ``still``: plans whose first interval moves the object not at all (its twist is zero: the
  active group has no robot in contact, or the object's match on the route is at the subgoal
  already), and of those ``still_pushing`` with a robot told to push;
- ``planned_m`` and ``moved_m``: how far the plans' first intervals said the centroid would go,
  summed, against how far it really went (the world's truth) over the same intervals; the same
  for the distance gained toward the goal's centroid (``*_toward_m``) and the turn (``*_deg``);
- ``turn_deg``: the object's largest turn from its start heading (truth);
- for a run that failed: the same counts over the last ``transport.stall_timeout`` seconds
  before the failure (``stall``), where the object made no progress.

Usage: ``python bench/serpentine_traces.py [--scenarios 16] [--workers 2]``. A run takes
about half a minute to a minute and a half of wall time on a quiet 2-core machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.transport_loop import draw_varied_suite  # noqa: E402


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _truth_at(track: np.ndarray, t: float) -> np.ndarray:
    """The object's true pose (x, y, θ) at time t (the last sample at or before it)."""
    k = max(int(np.searchsorted(track[:, 0], t, side="right")) - 1, 0)
    return track[k, 1:]


def _counts(plans: list[dict], track: np.ndarray, centroid: np.ndarray, goal: np.ndarray) -> dict:
    """The plans' counts, and their first intervals' planned against true centroid motion:
    distance, distance gained toward the goal's centroid, and turn."""
    from controller import geometry

    feasible = two = still = still_pushing = 0
    got = dict.fromkeys(("planned_m", "moved_m", "planned_toward_m", "moved_toward_m"), 0.0)
    got.update(planned_turn_deg=0.0, turned_deg=0.0)

    def centre(pose) -> np.ndarray:
        return geometry.transform(centroid[None], np.asarray(pose, float))[0]

    for p in plans:
        d = p["data"]
        feasible += (d.get("lp_status") or ["none"])[0] == "optimal"
        two += d.get("serpentine_groups") == 2
        poses = d.get("object_poses") or []
        if len(poses) < 2 or poses[0][0] is None or poses[1][0] is None:
            continue
        t0, dt = p["t"], float(d["interval"])
        if np.allclose(poses[0], poses[1], atol=1e-6):  # the first interval moves nothing
            still += 1
            still_pushing += "push" in (d.get("actions") or [[]])[0]
        for kind, (qa, qb) in (
            ("planned", poses[:2]),
            ("moved", (_truth_at(track, t0), _truth_at(track, t0 + dt))),
        ):
            a, b = centre(qa), centre(qb)
            got[f"{kind}_m"] += float(np.linalg.norm(b - a))
            got[f"{kind}_toward_m"] += float(np.linalg.norm(a - goal) - np.linalg.norm(b - goal))
            turn = abs(math.degrees(geometry.wrap_angle(float(qb[2]) - float(qa[2]))))
            got["planned_turn_deg" if kind == "planned" else "turned_deg"] += turn
    return {
        "plans": len(plans),
        "first_lp_feasible": feasible,
        "two_groups": two,
        "still": still,
        "still_pushing": still_pushing,
        **{k: round(v, 3) for k, v in got.items()},
    }


def run_case(sc) -> dict:
    """One serpentine run of a scenario, its log read back (in a worker process)."""
    from controller import geometry
    from controller.mission.factory import build_mission
    from controller.replay.log import load_run
    from controller.runtime.dry_run import DryRun
    from tests.support.transport_scenarios import scenario_config

    patch = {**sc.patch, "transport": {**sc.patch.get("transport", {}), "strategy": "serpentine"}}
    sc = dataclasses.replace(sc, patch=patch)
    cfg = scenario_config(sc)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.mcap"
        res = DryRun(cfg, build_mission(cfg, "transport"), path).run()
        run = load_run(path)
    track = np.asarray(run.object_truth, float)
    centroid = geometry.centroid(geometry.ensure_ccw(cfg.object_polygon()))
    goal = geometry.transform(centroid[None], np.asarray(cfg.object.goal, float))[0]
    plans = [e for e in run.events if e["kind"] == "transport" and e["data"].get("strategy")]
    plans = [e for e in plans if e["data"].get("status") == "ok"]
    start = float(track[0, 3])
    turn = float(np.max(np.abs([geometry.wrap_angle(th - start) for th in track[:, 3]])))
    out = {
        "scenario": sc.name,
        "shape": sc.name.split("-", 2)[2],
        "robots": len(sc.kinds),
        "outcome": "delivered" if res.get("transported") else (res.get("reason") or "failed"),
        "failed_at_s": (res.get("failure") or {}).get("t"),
        "turn_deg": round(math.degrees(turn), 1),
        **_counts(plans, track, centroid, goal),
    }
    fail_t = out["failed_at_s"]
    if fail_t is not None and not res.get("transported"):
        window = cfg.transport.stall_timeout
        late = [p for p in plans if fail_t - window <= p["t"] <= fail_t]
        out["stall"] = {"window_s": window, **_counts(late, track, centroid, goal)}
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    log(
        f"  {sc.name}: {out['outcome']}, {out['plans']} plans, first LP feasible "
        f"{out['first_lp_feasible']}, toward the goal planned {out['planned_toward_m']} m, "
        f"moved {out['moved_toward_m']} m; turned {out['turned_deg']}° (planned "
        f"{out['planned_turn_deg']}°), wall {out['wall_s']} s"
    )
    return out


def summary(runs: list[dict]) -> dict:
    """The counts over every run and over the stalled ones' last window."""

    def pool(rows: list[dict]) -> dict:
        keys = ("plans", "first_lp_feasible", "two_groups", "still", "still_pushing",
                "planned_m", "moved_m",
                "planned_toward_m", "moved_toward_m", "planned_turn_deg", "turned_deg")  # fmt: skip
        return {"runs": len(rows), **{k: round(sum(r[k] for r in rows), 2) for k in keys}}

    failed = [r for r in runs if r["outcome"] != "delivered"]
    turns = [r["turn_deg"] for r in failed]
    return {
        "all": pool(runs),
        "failed_runs": len(failed),
        "outcomes": {o: sum(r["outcome"] == o for r in runs) for o in {r["outcome"] for r in runs}},
        "stall_windows": pool([r["stall"] for r in failed if "stall" in r]),
        "failed_turn_deg": {
            "median": float(np.median(turns)) if turns else None,
            "min": min(turns, default=None),
            "max": max(turns, default=None),
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=16)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    suite = draw_varied_suite(args.scenarios)
    log(f"serpentine traces: {len(suite)} runs on {args.workers} workers ...")
    if args.workers <= 1:
        runs = [run_case(sc) for sc in suite]
    else:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            runs = list(pool.map(run_case, suite))
    out = {
        "bench": "serpentine_traces",
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "size": {"scenarios": args.scenarios},
        "summary": summary(runs),
        "runs": runs,
        "wall_s": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
