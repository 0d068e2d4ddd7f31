"""SA vs downhill vs serpentine with spread: prints ONE JSON object on stdout (progress on stderr).

1. ``planner``: the energy landscape under the default settings (``TransportParams()``, the
   ``[transport]`` defaults). For every seeded planning case (``tests.support.transport_cases``
   push cases of 4-8 robots, shuffled or not, and the diamond with its rear robots following)
   and planner seed, ``sa`` and ``downhill`` plan from the same start; counted: SA's final
   energy strictly lower, equal, higher. Then, for the downhill finals, whether they are local
   minima of Code 1's neighbourhood (no single-entry change lowers the energy) and, of those,
   how often SA found lower: that is what "SA escapes local minima" can mean here.
2. ``closed_loop``: ``--seeds`` × ``--scenarios`` (the seeded suite of bench/transport_loop.py,
   never tuned on) × strategies, each a whole ``fleet run --mission transport`` in lockstep on
   ``--backend`` (pybullet by default: only it measures contact forces). Per strategy: success
   on our criterion (delivered within the position *and* heading tolerance, clean verdict) and
   on Sharma's (the CG, the object's centroid, within the position tolerance of the goal's
   centroid at its first arrival there, §5's stopping rule, heading free, robots never
   touching), each with its
   95 % Wilson interval; median transport time and contact impulse Σ|f|·dt with n and a 95 %
   bootstrap interval (over the runs each strategy delivered). Paired per (scenario, seed):
   McNemar's exact test on success, Wilcoxon's signed-rank test on time and impulse (runs both
   delivered) with n, the median paired ratio, and Holm's adjustment across every pairwise test
   of the table (``p_holm``; ``bench/stats.py``).
3. ``--sweep N``: the robustness runs (one open-floor crate, 3 m) with Yamashita's robot motion
   errors (``sim.robot_position_error`` = ±0.04 m, ±0.01 m) plus the world's object off
   (mass, floor friction ×U(0.9, 1.1), CoM ±1 cm; pybullet only), N runs per strategy.

Usage: ``python bench/transport_compare.py [--seeds 5] [--scenarios 2] [--sweep 0]
[--workers 2] [--backend pybullet] [--planner-seeds 10] [--rows runs.jsonl] [--retry-invalid]``.
A closed-loop run takes about a minute of wall time on a quiet 2-core machine (more under load):
size the run to the machine. ``--rows``: each run's row is appended as it ends, and a bench run
again with the same file skips the runs already there (a killed bench resumes). A run whose
lockstep missed a tick is not the seed's reproducible run: it is marked ``valid: false``, left
out of the statistics and listed in ``invalid_runs`` (``--retry-invalid`` runs it once more).
``--merge A.json B.json ...`` pools outputs (a later file's run replaces an earlier one's),
``--table OUT.json`` prints the table of docs/results/transport.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import stats  # noqa: E402
from bench.transport_loop import draw_suite, draw_varied_suite, sweep_suite  # noqa: E402
from controller.planning.transport import plan_local  # noqa: E402
from controller.planning.transport_model import Rollout  # noqa: E402
from controller.planning.transport_types import ACTIONS, TransportParams  # noqa: E402
from tests.support.transport_cases import diamond_case, push_case  # noqa: E402

STRATEGIES = ("sa", "downhill", "serpentine")
#: Yamashita et al.'s Table 1 (condition 2): the error model ``transport.errors`` plans with;
#: a strategy named ``<strategy>+errors`` runs with it, the plain name without (condition 1)
YAMASHITA_ERRORS = {"position": [0.04, 0.01], "mass": 0.1, "friction": 0.1, "com": 0.01}
#: ``<strategy>+<name>``: the error model the plans allow for (``pose``: the motion error only)
ERROR_MODELS = {"errors": YAMASHITA_ERRORS, "pose": {"position": [0.04, 0.01]}}
#: the serpentine's counts a run reports (``fleet run --json``'s ``mission``)
SERPENTINE_COUNTS = ("serpentine_plans", "serpentine_two_group_plans", "serpentine_switches")
#: the output's sets of runs and their labels in the table
SECTIONS = (("closed_loop", "suite"), ("robustness", "robustness"), ("varied", "varied"))


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- statistics
# (bench/stats.py: Wilson for rates, McNemar's exact test for paired success, Wilcoxon with n
# for paired times and impulses, Holm across a table's pairwise tests)


def signed_rank(diffs) -> dict:
    """Wilcoxon's signed-rank test of paired differences (``pairs``, ``wilcoxon_p``)."""
    out = stats.signed_rank(diffs)
    p = out["p"]
    return {
        "pairs": out["n"],
        "a_lower": out["a_lower"],
        "a_higher": out["a_higher"],
        "wilcoxon_p": None if p is None else float(f"{p:.3g}"),
    }


# --------------------------------------------------------------------------- 1. the planner


def planner_cases() -> list[tuple[str, object]]:
    from tests.unit.test_transport import with_actions

    out = [("diamond-both-following", with_actions(diamond_case(), ["follow", "follow"]))]
    for n in (4, 6, 8):
        for seed in (None, 1, 2):
            for fmax in (4.0, 8.0):
                out.append((f"push-{n}-f{fmax:g}-s{seed}", push_case(n, max_force=fmax, seed=seed)))
    return out


def local_minimum(state, params: TransportParams, matrix: np.ndarray) -> bool:
    """No single-entry change of ``matrix`` lowers the energy (Code 1's neighbourhood)."""
    roll = Rollout(state, params)
    trace = roll.run(matrix)
    e0 = roll.energy(trace).total
    n, k = matrix.shape
    for j in range(n):
        for i in range(k):
            for x in range(len(ACTIONS)):
                if x == matrix[j, i]:
                    continue
                m = matrix.copy()
                m[j, i] = x
                if roll.energy(roll.rerun(trace, m, j)).total < e0 - 1e-9:
                    return False
    return True


def planner_bench(seeds: int, minima_checks: int) -> dict:
    rows = []
    for name, st in planner_cases():
        for seed in range(seeds):
            e = {}
            for s in ("sa", "downhill"):
                plan = plan_local(st, TransportParams(strategy=s), np.random.default_rng(seed))
                e[s] = plan
            rows.append((name, seed, st, e["sa"], e["downhill"]))
    diffs = np.array([r[3].energy.total - r[4].energy.total for r in rows])
    tol = 1e-9
    out = {
        "settings": "TransportParams() defaults (iterations 100, T0 0.3, cooling 0.95, lp start)",
        "cases": len(planner_cases()),
        "seeds_per_case": seeds,
        "plans_each": len(rows),
        "sa_lower": int(np.sum(diffs < -tol)),
        "equal": int(np.sum(np.abs(diffs) <= tol)),
        "sa_higher": int(np.sum(diffs > tol)),
        "energy_diff_sa_minus_downhill": signed_rank(diffs),
    }
    log("  local-minimum checks ...")
    checked = minima = sa_below_at_minimum = 0
    for _name, _seed, st, sa, dh in rows[:minima_checks]:
        checked += 1
        if local_minimum(st, TransportParams(strategy="downhill"), dh.matrix):
            minima += 1
            sa_below_at_minimum += sa.energy.total < dh.energy.total - tol
    out["downhill_finals_checked"] = checked
    out["downhill_finals_at_a_local_minimum"] = minima
    out["of_those_sa_lower"] = sa_below_at_minimum
    return out


# --------------------------------------------------------------------------- 2. closed loop


def run_case(job: tuple) -> dict:
    """One closed-loop run (in a worker process)."""
    from controller.mission.factory import build_mission
    from controller.runtime.dry_run import DryRun, judge
    from tests.support.transport_scenarios import scenario_config

    sc, strategy, seed, label = job
    base, _, errors = strategy.partition("+")  # "sa+errors": Yamashita's condition 2
    transport = {**sc.patch.get("transport", {}), "strategy": base}
    if errors:
        transport["errors"] = ERROR_MODELS[errors]
    patch = {**sc.patch, "transport": transport}
    sc = dataclasses.replace(sc, patch=patch, seed=seed)
    cfg = scenario_config(sc)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        res = DryRun(cfg, build_mission(cfg, "transport"), Path(tmp) / "run.mcap").run()
    clean = judge(res) == []
    mission = res.get("mission") or {}
    ours = bool(res.get("transported")) and res.get("status") == "ok" and clean
    err = res.get("goal_error_m")
    # Sharma's criterion: the CG (the centroid) within the tolerance of the goal's, at its
    # first arrival (§5's stopping rule), heading free; never touching (a clean verdict)
    paper = clean and res.get("goal_centroid_reached_s") is not None
    log(
        f"  {label} {sc.name} seed {seed} {strategy}: {'ok' if ours else 'NOT'} "
        f"(paper {'ok' if paper else 'NOT'}, {res.get('reason') or ''}) "
        f"t={res.get('transport_time_s')} wall={time.perf_counter() - t0:.0f}s"
    )
    return {
        "scenario": sc.name,
        "seed": seed,
        "strategy": strategy,
        "success": ours,
        "success_paper": bool(paper),
        "reason": res.get("reason"),
        "goal_error_m": err,
        "goal_error_deg": res.get("goal_error_deg"),
        "goal_centroid_error_m": res.get("goal_centroid_error_m"),
        "goal_centroid_reached_s": res.get("goal_centroid_reached_s"),
        "transport_time_s": res.get("transport_time_s"),
        "impulse_ns": res.get("contact_impulse_ns"),
        "lateral_deviation_rms_m": res.get("lateral_deviation_rms_m"),
        "rearrangements": res.get("rearrangements"),
        # the truth about the robots the plan had pushing, and the robots' closest approach
        "push_contact_losses": res.get("push_contact_losses"),
        "push_contact_share": res.get("push_contact_share"),
        "min_clearance_m": res.get("min_clearance_m"),
        "verdict": [f["reason"] for f in judge(res)],
        # the mission's own figures (``mission`` in fleet run --json)
        **{k: mission.get(k) for k in SERPENTINE_COUNTS},
        "robots": len(sc.kinds),
        "kinds": sc.kinds,
        "heading_goal": sc.patch.get("transport", {}).get("heading_tolerance_deg", 0) < 180,
        "missed_ticks": res.get("missed_ticks"),
        # a run whose lockstep missed a tick (lockstep_lost: three in a row) is not the
        # reproducible run: left out of the statistics, counted, re-run with --retry-invalid
        "valid": not res.get("missed_ticks"),
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def aggregate(rows: list[dict], strategies, rng: np.random.Generator) -> dict:
    """Per strategy and paired, over the valid runs (rows written before ``valid`` existed
    count as valid); the invalid ones are counted in ``invalid_runs``."""
    invalid = [r for r in rows if not r.get("valid", True)]
    rows = [r for r in rows if r.get("valid", True)]
    out: dict = {
        "invalid_runs": [
            {k: r.get(k) for k in ("scenario", "seed", "strategy", "reason", "missed_ticks")}
            for r in invalid
        ]
    }
    for s in strategies:
        mine = [r for r in rows if r["strategy"] == s]
        ok = [r for r in mine if r["success"]]
        out[s] = {
            "runs": len(mine),
            "success": stats.rate([r["success"] for r in mine]),
            "success_paper_criterion": stats.rate([r["success_paper"] for r in mine]),
            "transport_time_s": stats.median([r["transport_time_s"] for r in ok], rng),
            "impulse_ns": stats.median([r["impulse_ns"] for r in ok], rng),
            "lateral_deviation_rms_m": stats.median(
                [r["lateral_deviation_rms_m"] for r in ok], rng
            ),
            "failures": sorted({str(r["reason"]) for r in mine if not r["success"]}),
        }
        if all("push_contact_losses" in r for r in mine):  # rows from before lack them
            losses = [r["push_contact_losses"] or 0 for r in mine]
            out[s].update(
                collisions=sum("collision" in (r.get("verdict") or []) for r in mine),
                push_contact_losses=int(sum(losses)),
                runs_with_contact_losses=sum(x > 0 for x in losses),
                push_contact_share=stats.median(
                    [r["push_contact_share"] for r in mine if r["push_contact_share"]], rng
                ),
            )
    pairs: dict = {}
    for i, a in enumerate(strategies):
        for b in strategies[i + 1 :]:
            ra = {(r["scenario"], r["seed"]): r for r in rows if r["strategy"] == a}
            rb = {(r["scenario"], r["seed"]): r for r in rows if r["strategy"] == b}
            keys = sorted(set(ra) & set(rb))
            both = [k for k in keys if ra[k]["success"] and rb[k]["success"]]
            p = {"paired_runs": len(keys), "both_delivered": len(both)}
            wins = [int(ra[k]["success"]) - int(rb[k]["success"]) for k in keys]
            p["success"] = {
                "pairs": len(keys),
                "only_a_delivered": wins.count(1),
                "only_b_delivered": wins.count(-1),
                "mcnemar_p": stats.mcnemar(wins.count(1), wins.count(-1)),
            }
            for key in ("transport_time_s", "impulse_ns"):
                good = [k for k in both if ra[k][key] and rb[k][key]]
                p[key] = signed_rank([ra[k][key] - rb[k][key] for k in good])
                ratios = [ra[k][key] / rb[k][key] for k in good]
                p[key]["median_ratio_a_over_b"] = (
                    round(float(np.median(ratios)), 3) if ratios else None
                )
            if all("push_contact_losses" in ra[k] and "push_contact_losses" in rb[k] for k in keys):
                # every paired run (delivered or not): contacts lost, and runs with a collision
                p["push_contact_losses"] = signed_rank(
                    [(ra[k]["push_contact_losses"] or 0) - (rb[k]["push_contact_losses"] or 0)
                     for k in keys]
                )  # fmt: skip
                hit = [
                    int("collision" in (ra[k].get("verdict") or []))
                    - int("collision" in (rb[k].get("verdict") or []))
                    for k in keys
                ]
                p["collision"] = {
                    "pairs": len(keys),
                    "only_a": hit.count(1),
                    "only_b": hit.count(-1),
                    "mcnemar_p": stats.mcnemar(hit.count(1), hit.count(-1)),
                }
            pairs[f"{a}_vs_{b}"] = p
    _holm(pairs)
    out["paired"] = pairs
    return out


def with_contact_friction(sc, mu: float):
    """The scenario with ``object.contact_friction`` = mu (world and planners alike)."""
    obj = {**sc.patch.get("object", {}), "contact_friction": mu}
    return dataclasses.replace(sc, patch={**sc.patch, "object": obj})


def with_world_errors(sc):
    """The scenario's world off as Yamashita's Table 1 has it: robot motion errors (±0.04 m,
    ±0.01 m), the object's mass and floor friction ×U(0.9, 1.1) and its CoM ±1 cm, drawn from
    the scenario's seed (the controller is told the nominal object)."""
    rng = np.random.default_rng([sc.seed, 5050])
    sim = {
        **sc.patch.get("sim", {}),
        "robot_position_error": [0.04, 0.01],
        "object_mass_scale": round(float(rng.uniform(0.9, 1.1)), 4),
        "object_friction_scale": round(float(rng.uniform(0.9, 1.1)), 4),
        "object_com_offset": [round(float(v), 4) for v in rng.uniform(-0.01, 0.01, 2)],
    }
    return dataclasses.replace(sc, patch={**sc.patch, "sim": sim})


def eq5_groups(sc) -> dict:
    """Whether Eq. 5's pushing set for the scenario's straight line (as many pushers as
    robots, Sharma §4.1, as the serpentine asks for it) splits into Sharma's two groups: the
    serpentine can only alternate where both have members."""
    from controller import geometry
    from controller.planning.arrangement import pushing_set
    from controller.planning.serpentine import split_groups
    from tests.support.transport_scenarios import scenario_config

    cfg = scenario_config(sc)
    start, goal = np.asarray(sc.start, float), np.asarray(sc.goal, float)
    d = goal[:2] - start[:2]
    d /= np.linalg.norm(d)
    local = geometry.rot(float(start[2])).T @ d
    pts, nrm, _ = pushing_set(cfg, local, len(sc.kinds), np.random.default_rng(sc.seed))
    c = geometry.centroid(geometry.ensure_ccw(cfg.object_polygon()))
    groups = split_groups(-nrm, pts - c, local)  # in the object's frame
    return {
        "scenario": sc.name,
        "shape": sc.name.split("-", 2)[2],
        "robots": len(sc.kinds),
        "pushers_forward": int(np.sum(groups >= 0)),
        "group_sizes": [int(np.sum(groups == 0)), int(np.sum(groups == 1))],
        "two_groups": bool(np.sum(groups == 0) and np.sum(groups == 1)),
    }


def _holm(pairs: dict) -> None:
    """Holm's adjustment across every pairwise test of the table (success, time, impulse of
    each pair): each test gains ``p_holm``."""
    keys = ("success", "transport_time_s", "impulse_ns", "push_contact_losses", "collision")
    tests = [(p, key) for p in pairs.values() for key in keys if key in p]
    raw = [p[key].get("mcnemar_p", p[key].get("wilcoxon_p")) for p, key in tests]
    for (p, key), adj in zip(tests, stats.holm(raw), strict=True):
        p[key]["p_holm"] = None if adj is None else float(f"{adj:.3g}")


def _key(r: dict) -> tuple:
    """A row's run: its set, scenario, seed and strategy."""
    return (r.get("label", ""), r["scenario"], r["seed"], r["strategy"])


def _job_key(job: tuple) -> tuple:
    sc, strategy, seed, label = job
    return (label, sc.name, seed, strategy)


def run_all(
    jobs: list[tuple], workers: int, rows_file: Path | None = None, retry_invalid: bool = False
) -> list[dict]:
    """Every job's row. ``rows_file`` (JSON lines): each row appended as its run ends, and the
    jobs whose valid row is there already are not run again (a killed bench resumes).
    ``retry_invalid``: a run whose lockstep missed ticks is run once more."""
    done: dict = {}
    if rows_file is not None and rows_file.exists():
        for line in rows_file.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if r.get("valid", True):
                    done[_key(r)] = r
    todo = [j for j in jobs if _job_key(j) not in done]
    if len(todo) < len(jobs):
        log(f"  {len(jobs) - len(todo)} runs read back from {rows_file}")

    def run(batch: list[tuple]) -> list[dict]:
        if workers <= 1:
            return [_keep(job, run_case(job), rows_file) for job in batch]
        got: dict = {}
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(run_case, job): i for i, job in enumerate(batch)}
            for fut in as_completed(futures):  # written as each ends, not in job order
                i = futures[fut]
                got[i] = _keep(batch[i], fut.result(), rows_file)
        return [got[i] for i in range(len(batch))]

    new = run(todo)
    if retry_invalid:
        again = [j for j, r in zip(todo, new, strict=True) if not r["valid"]]
        if again:
            log(f"  {len(again)} runs missed lockstep ticks: running them once more")
            redo = {_key(r): r for r in run(again)}
            new = [redo.get(_key(r), r) for r in new]
    got = {**done, **{_key(r): r for r in new}}
    return [got[_job_key(j)] for j in jobs]


def _keep(job: tuple, row: dict, rows_file: Path | None) -> dict:
    """The row with its set's label, appended to ``rows_file`` (if any) right away."""
    row = {**row, "label": job[3]}
    if rows_file is not None:
        with rows_file.open("a") as f:
            f.write(json.dumps(row, default=lambda x: None if x is None else float(x)) + "\n")
    return row


def _num(v: float) -> str:
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"


def _p(v: float | None) -> str:
    return "–" if v is None else ("< 1e-4" if v < 1e-4 else f"{v:.2g}")


def _ci(x: dict, key: str, unit: str = "") -> str:
    if x.get(key) is None:
        return "–"
    lo, hi = x["ci95"]
    return f"{_num(x[key])}{unit} [{_num(lo)}, {_num(hi)}]"


def table(out: dict) -> str:
    """The results page's comparison table (markdown) from this script's JSON."""
    lines = []
    for sec, label in SECTIONS:
        if sec not in out:
            continue
        for s, r in out[sec].items():
            if s in ("paired", "invalid_runs"):
                continue
            ok, paper = r["success"], r["success_paper_criterion"]
            lines.append(
                f"| {label} | `{s}` | {r['runs']} | {_ci({**ok, 'rate': ok['rate']}, 'rate')} "
                f"| {_ci(paper, 'rate')} | {_ci(r['transport_time_s'], 'median', ' s')} "
                f"| {_ci(r['impulse_ns'], 'median', ' N·s')} |"
            )
        for pair, p in out[sec]["paired"].items():
            w = p["success"]
            parts = [
                f"success: only first {w.get('only_a_delivered', w.get('a_lower'))}, only "
                f"second {w.get('only_b_delivered', w.get('a_higher'))} (McNemar p "
                f"{_p(w.get('mcnemar_p', w.get('wilcoxon_p')))}, Holm {_p(w.get('p_holm'))})"
            ]
            for key, name in (("transport_time_s", "time"), ("impulse_ns", "impulse")):
                q = p[key]
                parts.append(
                    f"{name}: ratio {q['median_ratio_a_over_b']}, first lower in "
                    f"{q['a_lower']}/{q['pairs']} (Wilcoxon p {_p(q['wilcoxon_p'])}, Holm "
                    f"{_p(q.get('p_holm'))})"
                )
            lines.append(
                f"| {label} | {pair.replace('_vs_', ' vs ')} | paired | "
                + "; ".join(parts)
                + " | | | |"
            )
    head = (
        "| set | strategy | runs | success (ours) [95 % Wilson] | success (Sharma: CG only) "
        "| time, median [CI] | impulse, median [CI] |"
    )
    notes = [
        f"{label}: {len(out[sec].get('invalid_runs', []))} runs left out (lockstep ticks missed)"
        for sec, label in SECTIONS
        if out.get(sec, {}).get("invalid_runs")
    ]
    return "\n".join([head, "|---|---|---|---|---|---|---|", *lines, *notes])


def merge(paths: list[str], strategies, rng: np.random.Generator) -> dict:
    """The runs of several outputs pooled (a run repeated in two files counts once) and
    aggregated again: the statistics of chunked runs are those of one run over all their seeds."""
    outs = [json.loads(Path(p).read_text()) for p in paths]
    merged: dict = {"bench": "transport_compare", "merged_from": paths}
    for sec, _ in SECTIONS:
        runs: dict = {}
        for o in outs:
            for r in o.get(f"{sec}_runs", []):
                runs[(r["scenario"], r["seed"], r["strategy"])] = r
        if runs:
            rows = list(runs.values())
            merged[sec] = aggregate(rows, strategies, rng)
            merged[f"{sec}_runs"] = rows
    for o in outs:
        if "planner" in o:
            merged["planner"] = o["planner"]
    merged["wall_s"] = round(sum(o.get("wall_s", 0.0) for o in outs), 1)
    merged["load_average"] = [o.get("load_average") for o in outs]
    return merged


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--table", nargs="+", metavar="JSON", help="print the results page's table")
    ap.add_argument("--seeds", type=int, default=5, help="closed-loop seeds per scenario")
    ap.add_argument(
        "--seed-from", type=int, default=0, help="first seed index (to run the seeds in chunks)"
    )
    ap.add_argument(
        "--merge",
        nargs="+",
        metavar="JSON",
        help="pool the runs of several outputs (chunks of seeds) and aggregate them again",
    )
    ap.add_argument("--scenarios", type=int, default=2)
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--backend", default="pybullet", choices=("pybullet", "ideal"))
    ap.add_argument("--sweep", type=int, default=0, help="robustness runs per strategy")
    ap.add_argument(
        "--varied", type=int, default=0, help="scenarios of the varied suite (one run each)"
    )
    ap.add_argument(
        "--contact-friction",
        type=float,
        default=None,
        help="object.contact_friction for every run (the world's robot-object friction and the "
        "LP's friction cones; default: the scenarios' own, 0)",
    )
    ap.add_argument(
        "--world-errors",
        action="store_true",
        help="the varied suite's worlds off as the robustness runs' are: robot motion errors "
        "±0.04 m, ±0.01 m, the object's mass and floor friction ×U(0.9, 1.1), CoM ±1 cm",
    )
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--planner-seeds", type=int, default=10)
    ap.add_argument("--minima-checks", type=int, default=40)
    ap.add_argument(
        "--rows",
        metavar="JSONL",
        help="append each run's row here as it ends; runs already there are not run again",
    )
    ap.add_argument(
        "--retry-invalid",
        action="store_true",
        help="run once more a run whose lockstep missed ticks (its outcome is not the seed's)",
    )
    args = ap.parse_args()
    rows_file = Path(args.rows) if args.rows else None
    if args.table:
        merged: dict = {}
        for path in args.table:
            merged.update(json.loads(Path(path).read_text()))
        print(table(merged))
        return
    strategies = tuple(args.strategies.split(","))
    rng = np.random.default_rng(2024)
    if args.merge:
        print(json.dumps(merge(args.merge, strategies, rng), indent=1))
        return
    t0 = time.perf_counter()
    out: dict = {
        "bench": "transport_compare",
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "size": {
            "seeds": args.seeds,
            "seed_from": args.seed_from,
            "scenarios": args.scenarios,
            "strategies": list(strategies),
            "backend": args.backend,
            "sweep_runs_per_strategy": args.sweep,
            "varied_scenarios": args.varied,
            "contact_friction": args.contact_friction,
            "world_errors": args.world_errors,
            "planner_seeds": args.planner_seeds,
        },
    }
    if args.planner_seeds:
        log("planner: sa vs downhill from the same start, default settings ...")
        out["planner"] = planner_bench(args.planner_seeds, args.minima_checks)
    suite = [dataclasses.replace(s, backend=args.backend) for s in draw_suite(args.scenarios)]
    jobs = [
        (sc, strat, 100 + 17 * k + seed, "suite")
        for k, sc in enumerate(suite)
        for seed in range(args.seed_from, args.seed_from + args.seeds)
        for strat in strategies
    ]
    if jobs:
        log(f"closed loop: {len(jobs)} runs on {args.workers} workers ...")
        rows = run_all(jobs, args.workers, rows_file, args.retry_invalid)
        out["closed_loop"] = aggregate(rows, strategies, rng)
        out["closed_loop_runs"] = rows
    if args.sweep:
        sweep = []
        for k, sc in enumerate(sweep_suite(args.sweep)):
            sim = {**sc.patch["sim"], "robot_position_error": [0.04, 0.01]}
            sc = dataclasses.replace(sc, backend=args.backend, patch={**sc.patch, "sim": sim})
            sweep += [(sc, strat, 200 + k, "sweep") for strat in strategies]
        log(f"robustness: {len(sweep)} runs ...")
        rows = run_all(sweep, args.workers, rows_file, args.retry_invalid)
        out["robustness"] = aggregate(rows, strategies, rng)
        out["robustness_runs"] = rows
    if args.varied:
        varied = draw_varied_suite(args.varied)
        if args.world_errors:
            varied = [with_world_errors(sc) for sc in varied]
        if args.contact_friction is not None:
            varied = [with_contact_friction(sc, args.contact_friction) for sc in varied]
        out["eq5_groups"] = [eq5_groups(sc) for sc in varied]
        jobs = [(dataclasses.replace(sc, backend=args.backend), strat, sc.seed, "varied")
                for sc in varied for strat in strategies]  # fmt: skip
        log(f"varied: {len(jobs)} runs ...")
        rows = run_all(jobs, args.workers, rows_file, args.retry_invalid)
        out["varied"] = aggregate(rows, strategies, rng)
        out["varied_runs"] = rows
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=1, default=lambda x: None if x is None else float(x)))


if __name__ == "__main__":
    main()
