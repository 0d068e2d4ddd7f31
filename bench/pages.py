"""The results pages' figures, written from the committed rows (``bench/rows/*.json``).

    python bench/pages.py           # rewrite the generated blocks of docs/results/*.md
    python bench/pages.py --check   # exit 1 naming the blocks that are not current

A results page holds hand-written text and generated blocks; a block is everything between

    <!-- rows: NAME -->
    <!-- /rows -->

and is written here from ``bench/rows/NAME.json`` (made by ``python bench/record.py NAME``)
by the renderer of that name: figures rounded, goals stated met or missed, and the row's
provenance (command, commit, date, machine, load) under the figures. A block whose row is
missing says so rather than keeping old numbers.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.stats import mcnemar, wilson  # noqa: E402

ROWS = ROOT / "bench" / "rows"
PAGES = ROOT / "docs" / "results"
BLOCK = re.compile(r"(<!-- rows: (?P<name>[a-z_]+) -->\n)(?P<body>.*?)(<!-- /rows -->)", re.S)


def _ms(x: float) -> str:
    return f"{x:.2f} ms" if x < 10 else f"{x:.1f} ms"


def _us(x: float) -> str:
    return f"{x:.0f} µs" if x >= 10 else f"{x:.1f} µs"


def _met(flag: object) -> str:
    return "**met**" if flag else "**not met**"


def _table(head: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def provenance(row: dict) -> str:
    m = row.get("machine", {})
    name = row.get("row", row["bench"])
    args = row["command"].split()[2:]
    again = f"python bench/record.py {row['bench']}"
    if name != row["bench"]:
        again += f" --as {name}"
    if args:
        again += " -- " + " ".join(args)
    dirty = " (with uncommitted changes)" if row.get("dirty") else ""
    code = row.get("exit")
    failed = f"; the bench exited {code} (a failure among its figures)" if code else ""
    lb, la = row.get("load_before") or [0], row.get("load_after") or [0]
    loop = m.get("loop_1e7_s")
    speed = f", 10^7 Python additions in {loop:.2f} s" if loop else ""
    return (
        f"*Row `bench/rows/{name}.json`: `{row['command']}` at commit "
        f"`{row.get('commit') or '?'}`{dirty}, {row.get('date', '?')}; {m.get('cores', '?')} "
        f"cores, Python {m.get('python', '?')}{speed}; load {lb[0]:.1f} before, {la[0]:.1f} after"
        f"{failed}. "
        f"Again: `{again}` then `python bench/pages.py`.*"
    )


def approach(r: dict) -> str:
    sizes = r["sizes"]
    rows = []
    for n, s in sizes.items():
        rows.append(
            [
                n,
                _ms(s["planner"]["median_ms"]),
                _ms(s["filter_warm"]["median_ms"]),
                _ms(s["filter_warm_half_differential"]["median_ms"]),
                _ms(s["filter_cold_rebuild"]["median_ms"]),
                f"{s['speedup_median']:.1f}×",
            ]
        )
    head = ["robots", "projective planner", "filter, warm", "filter, half differential",
            "filter, cold rebuild", "warm vs cold"]  # fmt: skip
    return (
        "Per control tick, medians. The filter warm-started on its fixed sparsity pattern "
        "(ours) against the same QP set up cold every call, in the same process; half "
        "differential: the second solve with their axis rows.\n\n"
        + _table(head, rows)
        + f"\n\nGoal: {r['goal']}: {_met(r['goal_met'])}."
    )


def contact_lp(r: dict) -> str:
    cells = [k for k in r if k.startswith("n") and isinstance(r[k], dict) and "default" in r[k]]
    rows = []
    for c in cells:
        d = r[c]
        n, mu = c[1:].split("_mu")
        rows.append(
            [
                n,
                mu,
                _us(d["default"]["median_us"]),
                _us(d["default"]["p95_us"]),
                _us(d["highs"]["median_us"]),
                f"{d['default']['speedup_vs_highs']:.1f}×",
                f"{100 * d['default']['highs_fallback_share']:.2f} %",
                f"{100 * d['no_rescue']['highs_fallback_share']:.2f} %",
                str(d["default"]["disagreements"]),
            ]
        )
    head = ["contacts", "μ_c", "osqp median", "osqp p95", "HiGHS median", "speed-up",
            "fallbacks to HiGHS", "without the rescue", "disagreements"]  # fmt: skip
    knobs = []
    d = r.get("n8_mu0.3", {})
    for k, v in d.items():
        if isinstance(v, dict) and "median_us" in v and k not in ("default", "highs"):
            knobs.append(
                [
                    k,
                    _us(v["median_us"]),
                    f"{100 * v['highs_fallback_share']:.2f} %",
                    f"{v['median_us'] / d['default']['median_us']:.2f}×",
                ]  # fmt: skip
            )
    s = r["summary"]
    return (
        f"{cells and r[cells[0]]['problems']} seeded random LPs per cell, osqp (ours, "
        "warm-started, with the rescue of an answer it stops short on: a Farkas test or an "
        "active-set dual bound) against scipy's HiGHS `linprog` on the same problems in the "
        "same process. A fallback is an LP handed to HiGHS; a disagreement a different "
        "feasibility or objective.\n\n"
        + _table(head, rows)
        + f"\n\nFriction costs {s['friction_slowdown_8']:.1f}× at 8 contacts. Goal: "
        f"fewer than 1 % fallbacks in every cell: {_met(s['fallback_goal_1pct_met'])}.\n\n"
        "One knob at a time (8 contacts, μ_c 0.3), against the default:\n\n"
        + _table(["variant", "median", "fallbacks", "time vs default"], knobs)
    )


def estimation(r: dict) -> str:
    st, tk = r["step_us"], r["tick_ms"]
    rows = [
        ["linear KF (baseline)", _us(st["baseline_linear_kf"]), "1.0×"],
        ["EKF, omni", _us(st["ekf_omni"]), f"{st['ekf_omni_over_baseline']:.1f}×"],
        ["EKF, differential", _us(st["ekf_diff"]), f"{st['ekf_diff_over_baseline']:.1f}×"],
        ["UKF, omni", _us(st["ukf_omni"]), f"{st['ukf_omni_over_baseline']:.1f}×"],
        ["UKF, differential", _us(st["ukf_diff"]), f"{st['ukf_diff_over_baseline']:.1f}×"],
    ]
    acc = r["accuracy"]
    arows = []
    for k in ("ekf_omni", "ekf_diff", "ukf_omni", "ukf_diff"):
        a = acc[k]
        arows.append(
            [
                k.replace("_", ", "),
                f"{a['rmse_ratio_vs_inlier_measurements']:.2f}",
                f"{100 * a['outliers_rejected']:.0f} %",
                f"{100 * a['good_rejected']:.0f} %",
                f"{a['heading_max_err_deg']:.1f}°",
            ]  # fmt: skip
        )
    o = acc["ekf_object_sine_0.5s"]
    return (
        "One filter step (predict and update, filterpy), median:\n\n"
        + _table(["filter", "step", "vs baseline"], rows)
        + f"\n\nOne tick of 50 robots ({tk['measurements_per_robot_per_tick']:.2f} "
        f"measurements per robot): EKF {_ms(tk['ekf_50_robots'])} (p95 "
        f"{_ms(tk['ekf_50_robots_p95'])}), UKF {_ms(tk['ukf_50_robots'])} (p95 "
        f"{_ms(tk['ukf_50_robots_p95'])}).\n\n"
        f"Accuracy, worst of {acc['seeds']} seeds (RMSE against the inlier measurements' RMSE: "
        "below 1 is better than the raw poses):\n\n"
        + _table(
            ["filter", "RMSE ratio", "outliers rejected", "good rejected", "heading, worst"], arows
        )  # fmt: skip
        + f"\n\nThe object on its sine path, predicted 0.5 s ahead: {o['prediction_rmse_m']:.3f} m "
        f"RMSE against {o['hold_last_rmse_m']:.3f} m for holding the last pose "
        f"({o['ratio']:.2f}×)."
    )


def sim(r: dict) -> str:
    rows = []
    for n in r["real_time_factor"]:
        rows.append(
            [
                n,
                f"{r['real_time_factor'][n]:.1f}",
                f"{r['steps_per_s'][n]:,.0f}",
                f"{r['physics_only_steps_per_s'][n]:,.0f}",
                f"{r['ideal'][n]['steps_per_s']:,.0f}",
                f"{r['ideal'][n]['real_time_factor']:.1f}",
            ]  # fmt: skip
        )
    head = ["robots", "pybullet real-time factor", "steps/s", "bare stepSimulation steps/s",
            "ideal world steps/s", "ideal real-time factor"]  # fmt: skip
    return (
        f"The stand-in world at {r['timestep_hz']:.0f} Hz, robots and a live object:\n\n"
        + _table(head, rows)
        + f"\n\nGoal: a real-time factor of at least 5 at 16 robots: {_met(r['goal_rtf_16_met'])}."
    )


def bus(r: dict) -> str:
    raw, codec = r["round_trip_raw"], r["round_trip_codec"]
    rows = [
        ["raw bytes", _ms(raw["median_ms"]), _ms(raw["p99_ms"]), "1.0×"],
        [
            "our codec (Twist2D out, Pose2D back)",
            _ms(codec["median_ms"]),
            _ms(codec["p99_ms"]),
            f"{r['codec_over_raw_median']:.1f}×",
        ],  # fmt: skip
    ]
    return (
        f"A {r['payload_bytes']}-byte command's round trip between two processes on loopback "
        f"over zenoh, {raw['n']} of each, interleaved:\n\n"
        + _table(["round trip", "median", "p99", "vs raw"], rows)
        + f"\n\nEncode and decode: {_us(r['codec_encode_decode_us'])}. One way, reliable "
        f"and blocking: {r['throughput_msgs_per_s']:,.0f} messages/s "
        f"({r['throughput_received']:,} of {r['throughput_sent']:,} received)."
    )


FLOOD_CASES = {
    "normal": "normal rate (30 Hz a robot)",
    "poses_10x": "10× the pose rate, every robot",
    "poses_max": "every robot as fast as a process can put",
    "big_4mib": "normal rate + 4 MiB payloads (10 Hz a key)",
    "one_robot_max": "one robot as fast as it can, the others normal",
}
FLOOD_BUSES = {
    "before": "a callback decoding on zenoh's thread (before issue 22)",
    "after": "a callback per sample, rate-limited, decoder thread (issue 22)",
    "rings": "a zenoh ring per key, read at the tick (today)",
}


def bus_flood(r: dict) -> str:
    rows = []
    for case, what in FLOOD_CASES.items():
        res = r["cases"].get(case)
        if res is None:
            continue
        for bus, how in FLOOD_BUSES.items():
            x = res[bus]
            dropped = sum(x["drops"].get(k, 0) for k in ("inbox_overflow", "rate_limited"))
            rows.append([what if bus == "before" else "", how, _ms(x["tick_p50_ms"]),
                         _ms(x["tick_p99_ms"]), f"{x['late_ticks'] + x['skipped_ticks']}",
                         f"{x['poses_taken']:,}", f"{dropped:,}"])  # fmt: skip
    ratios = "; ".join(
        f"{FLOOD_CASES[c]}: {res['tick_p99_rings_over_after']:.2f}×"
        for c, res in r["cases"].items()
        if res.get("tick_p99_rings_over_after") is not None
    )
    head = ["flood", "how the daemon reads poses", "tick p50", "p99", "late or skipped",
            "poses read", "dropped, counted"]  # fmt: skip
    return (
        f"The daemon's tick (`ControllerNode.tick`, hold mission, {r['robots']} robots, 20 Hz, "
        f"with the recorder's tap) for {r['seconds']:g} s while another process floods the "
        "robots' pose keys; the three ways of reading them run in one process, interleaved:\n\n"
        + _table(head, rows)
        + f"\n\nTick p99, rings over a callback per sample: {ratios}."
    )


def command_burst(r: dict) -> str:
    rows = []
    for c in r["cases"]:
        for name, how in (("express", "express (before)"), ("batched", "batched (today)")):
            x = c[name]
            rows.append([f"{c['robots']}, {c['load']}" if name == "express" else "", how,
                         f"{x['lost']:,} of {x['commands']:,}", f"{x['robots_losing']}",
                         f"{x['longest_run_lost']}", _ms(x["latency_p50_ms"]),
                         _ms(x["latency_p99_ms"])])  # fmt: skip
    head = ["robots, load", "command publisher", "lost", "robots losing", "most lost in a row",
            "latency p50", "p99"]  # fmt: skip
    return (
        f"One command per robot put back to back at {r['rate_hz']:g} Hz for {r['seconds']:g} s "
        "(the daemon's tick) through a zenoh router (the hub) to one session per robot (the "
        f"agents); `hogs`: a busy process per core ({r['hogs']}). Both publishers run in one "
        "process, interleaved. Latency: the command's stamp to the agent's receipt, of those "
        "delivered.\n\n" + _table(head, rows)
    )


def loop(r: dict) -> str:
    rows = []
    for x in r["sizes"]:
        t, c = x["tick_ms"], x["command_latency_ms"]
        plans = ", ".join(
            f"{k} {v['p50']:.2f} / {v['p99']:.2f} s"
            for k, v in sorted((x.get("plan_latency_s") or {}).items())
            if isinstance(v, dict) and v.get("p50") is not None
        )
        rows.append([x["mission"], str(x["robots"]), _ms(t["p50"]), _ms(t["p99"]),
                     f"{x['late_ticks']}", _ms(c["p50"]), _ms(c["p99"]),
                     "" if x.get("kill9_to_not_present_ms") is None
                     else f"{x['kill9_to_not_present_ms'] / 1e3:.2f} s", plans or "-"])  # fmt: skip
    head = ["mission", "robots", "tick p50", "p99", "late ticks", "command latency p50",
            "p99", "kill -9 to not present", "plans off the tick, p50 / p99"]  # fmt: skip
    load = r["load_avg_1_5_15_start"][0], r["load_avg_1_5_15_end"][0]
    return (
        f"The daemon's tick at {r['rate_hz']:g} Hz (sample → estimate → plan → safety → "
        f"publish, as `fleet daemon` wires it; {r['backend']} backend), the agents in processes "
        f"of their own ({r['agents']}); command latency: {r['latency']}. Load average "
        f"{load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n" + _table(head, rows)
    )


def mavlink(r: dict) -> str:
    lat = r["latency_ms"]
    rows = [
        [
            "our driver",
            _ms(lat["adapter"]["median"]),
            _ms(lat["adapter"]["p99"]),
            f"{lat['ratio']:.2f}×",
        ],  # fmt: skip
        [
            "raw pymavlink",
            _ms(lat["raw_pymavlink"]["median"]),
            _ms(lat["raw_pymavlink"]["p99"]),
            "1.00×",
        ],  # fmt: skip
    ]
    rates = [
        [
            n,
            f"{v['median']:.1f} Hz",
            f"{v['min']:.1f} Hz",
            f"{v['requested']:.0f} Hz",
            f"{v['healthy']} of {n}",
        ]  # fmt: skip
        for n, v in r["pose_rate_hz"].items()
    ]
    return (
        "A velocity command from `MavlinkDriver.send` to the vehicle (an emulator on UDP "
        f"loopback) having decoded it, {lat['adapter']['n']} samples, against pymavlink alone "
        "in the same process:\n\n"
        + _table(["path", "median", "p99", "vs raw"], rows)
        + "\n\nThe pose stream each robot's vehicle is asked for:\n\n"
        + _table(["robots", "median rate", "slowest", "asked for", "healthy"], rates)
    )


def logs(r: dict) -> str:
    rec = {x["robots"]: x for x in r["recorder"]}
    rows = []
    for b in r["builder"]:
        n = b["robots"]
        x = rec.get(n, {})
        rows.append(
            [
                str(n),
                _us(b["us_per_bus_message"]),
                f"{x.get('msgs_per_s_with_scene', 0):,}",
                f"{x.get('msgs_per_s_without', 0):,}",
                f"{x.get('time_ratio_with_over_without', 0):.2f}×",
                f"{x.get('kb_per_sim_second_with_scene', 0):.1f} / "
                f"{x.get('kb_per_sim_second_without', 0):.1f} kB",
            ]  # fmt: skip
        )
    head = ["robots", "scene builder per bus message", "recorder msg/s, with the scene",
            "without", "time, with over without", "per sim second, with / without"]  # fmt: skip
    d, c, v = r["dry_run"], r["check"], r["live_view"]
    return (
        "The MCAP recorder with and without the Foxglove scene channels (built from the bus "
        "messages it records):\n\n"
        + _table(head, rows)
        + f"\n\nA {d['robots']}-robot dry run of {d['sim_s']:.0f} sim s: "
        f"{d['wall_s_with_scene']:.2f} s wall with the scene, {d['wall_s_without']:.2f} s "
        f"without ({d['ratio']:.2f}×). The "
        f"regression replay of the golden capture log ({c['ticks']} ticks): "
        f"{c['sim_s_per_wall_s']:.1f} sim s per wall s, "
        f"{'agreeing' if c['ok'] else 'NOT agreeing'}. "
        f"The live view: {_us(v['us_per_offer'])} per offer, never blocking "
        f"({v['dropped']:,} of {v['offers']:,} offers dropped by its full queue, as designed)."
    )


ROUTE_LABEL = {
    "euclid": "(A) Euclid",
    "wavefront": "(B) Wavefront",
    "skeleton": "(C) Skeleton",
    "cost_to_go": "(D) Cost-to-go (ours)",
}


def _route_norm(v: float) -> str:
    return f"{v:.4f}" if v < 0.01 else f"{v:.2f}"


def route_tables(r: dict) -> str:
    bare, bound = r["bare_potentials"], r["with_manipulation_bound"]
    t2 = bare["table2"]
    goals = list(next(iter(t2["raw"].values())))
    paper2 = r["paper"]["table2"]
    rows2 = []
    for k, vals in t2["N_open_norm"].items():
        pap = paper2.get(k)
        rows2.append(
            [ROUTE_LABEL[k]]
            + [
                f"{_route_norm(v)} [{pap[i]:.2f}]" if pap else f"{_route_norm(v)} [–]"
                for i, v in enumerate(vals)
            ]  # fmt: skip
        )
    sk = bare["table3"]["skeleton"]
    paper3 = r["paper"]["table3"]
    names = {
        "1,0": "1, 0 (Dijkstra)",
        "1,1": "1, 1 (A*)",
        "0,1": "0, 1 (greedy)",
        "1,0.5": "1, 0.5",
    }
    rows3 = [
        [names.get(k, k), f"{_route_norm(v['N_open_norm'])} [{paper3[k][0]:.2f}]",
         f"{v['f_norm']:.2f} [{paper3[k][1]:.2f}]", f"{v['N_open']:,}", f"{v['cost_s']:.1f} s"]
        for k, v in sk.items()
    ]  # fmt: skip
    claims = "\n".join(
        f"- {'**holds**' if c['holds'] else '**does not hold**'}: {c['claim']}"
        + (f" ({c['note']})" if c.get("note") else "")
        for c in bare["claims"]
    )
    d_raw = bare["table2"]["raw"]["cost_to_go"]
    d_bound = bound["table2"]["raw"]["cost_to_go"]
    d_opt = bound["table3"]["cost_to_go"]["1,1"]["f_norm"]
    grid = " × ".join(str(g) for g in r["grid"])
    return (
        f"On the shipped map `{r['map']}` ({grid}: cells × cells × headings), the paper's "
        "potentials alone as the heuristic (no turn or manipulation bound). Table 2: N_open "
        f"normalised to (A) Euclid on {goals[0]}; the paper's figures in brackets.\n\n"
        + _table(["Table 2: potential", *goals], rows2)
        + f"\n\nTable 3 ({goals[-1]}, skeleton potential), normalised to Dijkstra:\n\n"
        + _table(["w_g, w_h", "N_open", "f", "N_open (raw)", "route cost"], rows3)
        + "\n\nThe paper's claims, judged on these figures:\n\n"
        + claims
        + "\n\nThe planner's default heuristic is neither potential: (D), the lattice's "
        "exact cost-to-go with the turn and manipulation bound, expanded "
        f"{min(v['N_open'] for v in d_bound.values()):,}–"
        f"{max(v['N_open'] for v in d_bound.values()):,} states on the four goals "
        f"({min(v['N_open'] for v in d_raw.values()):,}–"
        f"{max(v['N_open'] for v in d_raw.values()):,} without the bound); its route on "
        f"{goals[-1]} costs {d_opt:.2f}× Dijkstra's.\n\nThe set-ups differ, so magnitudes "
        "need not match:\n\n" + "\n".join(f"- {x}" for x in r["differences"])
    )


GA_NAME = {
    "ours": 'ours (`capture.ga = "ours"`, the default)',
    "paper": 'the paper\'s GA (`capture.ga = "paper"`)',
    "ours_tied": "ours, infeasible strings tied (as before)",
    "pygad_paper": "pygad, the paper's settings",
    "pygad_doc": "pygad as its documentation recommends",
}


def capture(r: dict) -> str:
    pb = r["paper_budget"]
    one, dflt = pb["one_thread"], pb["default_threads"]
    rows = [
        [k[1:], f"{v['evaluations']:,}", f"{v['median_seconds']:.3f} s",
         f"{v['median_cpu_seconds']:.3f} s", f"{dflt[k]['median_seconds']:.3f} s"]
        for k, v in one.items()
    ]  # fmt: skip
    large = [
        [
            k[1:],
            f"{v['seconds']:.2f} s",
            f"{v['peak_rss_mb']:.0f} MB",
            "yes" if v["feasible"] else "no",
        ]  # fmt: skip
        for k, v in r["large"].items()
    ]
    su = r["suite"]
    n = su["polygons"]
    ob = r["over_budget"]
    return (
        f"{r['evaluations_per_s']:,.0f} evaluations/s. The paper's budget (60 × 600 "
        "evaluations) by number of candidate nodes K:\n\n"
        + _table(
            ["K", "evaluations", "wall, one BLAS thread", "CPU", "wall, default threads"], rows
        )  # fmt: skip
        + f"\n\nGoal: {pb['goal']}: {_met(pb['goal_met'])} (CPU time: "
        f"{_met(pb['goal_met_cpu'])}).\n\n`plan_capture` end to end on large boundaries, "
        "each in a fresh process:\n\n"
        + _table(["K", "wall", "peak RSS", "feasible"], large)
        + f"\n\nGoal: K = 760 under 2 s and every run under 500 MB: "
        f"{_met(r['large_goal_met'])}. A spacing past the node budget fails in "
        f"{ob['seconds']:.2f} s with the reason `{ob['reason']}`.\n\n"
        f"Optimum hits against brute force on a fresh suite ({n} polygons, "
        f"{min(su['nodes'])}–{max(su['nodes'])} nodes, half concave, seed {su['seed']}, "
        "which no test uses), every GA with the same ranked fitness and budget:\n\n"
        + _hits(su)
        + f"\n\nGoal: ours at least 97 %: {_met(r['goal_hit_rate_met'])}."
    )


def _hits(su: dict) -> str:
    rows = [
        [
            GA_NAME.get(g, g),
            f"{v['hits']}/{v['runs']} ({100 * v['hit_rate']:.1f} %)",
            " / ".join(str(h) for h in v["hits_per_seed_set"]),
            f"{v['median_gap']:.3f}",
            f"{v['median_seconds']:.2f} s",
        ]  # fmt: skip
        for g in GA_NAME
        if (v := su.get(g))
    ]
    return _table(["GA", "optimum hits", "per seed set", "median gap", "median time"], rows)


def capture_fresh(r: dict) -> str:
    su = r["suite"]
    judged = (
        "every set judged under the paper's constraints (§2.5: the push normals span the plane, "
        "moments both ways, one robot per edge, spacing) and the optimum found by brute force "
        "under them"
        if su.get("closure") == "paper"
        else "every set judged under exact form closure, the optimum found by brute force under it"
    )
    return (
        f"A suite drawn for this comparison and never tuned on ({su['polygons']} polygons, "
        f"{min(su['nodes'])}–{max(su['nodes'])} nodes, seed {su['seed']}), each GA within the "
        f"paper's budget, {judged}; the gap is the share of the optimum's objective missed:\n\n"
        + _hits(su)
    )


def _s(x: float) -> str:
    return f"{x * 1e3:.0f} ms" if x < 1 else f"{x:.2f} s"


def route(r: dict) -> str:
    door = r["doorway"]
    d = door.get("0.1 m") or next(iter(v for k, v in door.items() if isinstance(v, dict)))
    obj = []
    for n, v in r["object"].items():
        if "error" in v:
            obj.append([f"{n}²", "failed: " + " ".join(v["error"]), "", "", "", ""])
            continue
        g = v["goals"].values()
        exp = [x["expanded"] for x in g]
        tables = [x["table_seconds"] for x in g]
        obj.append(
            [
                f"{n}² × {v['grid'][2]}",
                _s(v["cspace_seconds"]),
                f"{_s(min(tables))}–{_s(max(tables))}",
                f"{_s(min(x['search_seconds'] for x in g))}–{_s(v['max_search_seconds'])}",
                f"{min(exp):,}–{max(exp):,}",
                _s(v["max_total_seconds"]),
                f"{v['peak_rss_mb']:.0f} MB",
            ]  # fmt: skip
        )
    opt = r["optimality_128"]
    gaps = [x["default_gap_pct"] for x in opt.values()]
    sk = [x["skeleton_gap_pct"] for x in opt.values()]
    two = []
    for k, v in r["two_d"].items():
        two.append(
            [
                k.replace("_", " ") + "²",
                f"{v['ours_search_seconds'] * 1e3:.1f} ms",
                f"{v['pathfinding_search_seconds'] * 1e3:.1f} ms",
                f"{v['speedup_search_vs_search']:.1f}×",
                f"{v['speedup_with_builds']:.1f}×",
                f"{v['speedup_octile_only_search_vs_search']:.1f}×",
                "yes" if v["same_cost"] else "**no**",
            ]  # fmt: skip
        )
    head = ["size", "C-space", "cost-to-go table, per goal", "search, per goal", "expansions",
            "worst goal in all", "peak RSS"]  # fmt: skip
    head2 = ["grid", "ours, search", "`pathfinding`, search", "speed-up", "with grid builds",
             "octile heuristic alone", "same cost"]  # fmt: skip
    ring = d.get("clearance_beyond_ring_m")
    goals = []
    o = r["object"]
    if "max_total_seconds" in o.get("256", {}):
        goals.append(f"256², worst goal under 2 s: {_met(o['256']['max_total_seconds'] < 2)}")
    if "max_total_seconds" in o.get("512", {}):
        ok = o["512"]["max_total_seconds"] < 10 and o["512"]["peak_rss_mb"] < 1024
        goals.append(f"512², under 10 s and 1 GB: {_met(ok)}")
    room = r["two_d"].get("room_256")
    if room:
        goals.append(
            f"robot A* at least 4× `pathfinding`'s search on the room: "
            f"{_met(room['speedup_search_vs_search'] >= 4)}"
        )
    return (
        f"The doorway case ({door['crate_m']:g} m L carried by {door['robot_radius_m']:g} m "
        f"robots through a {door['doorway_m']:g} m door) at 0.1 m: {d['status']}, "
        f"{d['expanded']:,} expansions, {_s(d['seconds'])}"
        + (
            f"; the footprint keeps {ring:.3f} m beyond the robot ring (checked exactly)."
            if ring is not None
            else "."
        )  # fmt: skip
        + "\n\nThe object's search on the shipped map, every goal, default `[route]` "
        "(the `cost_to_go` heuristic), each size in its own process:\n\n"
        + _table(head, obj)
        + ("\n\nGoals: " + "; ".join(goals) + "." if goals else "")
        + f"\n\nOptimality at 128²: the default's routes are {min(gaps):.1f}–"
        f"{max(gaps):.1f} % above the optimum (A* with the admissible wavefront potential) "
        f"on the {len(gaps)} goals; the skeleton potential's {min(sk):.1f}–{max(sk):.1f} %."
        "\n\nRobot A* (`RobotRoadmap`, octile distance tightened by landmarks) against the "
        "`pathfinding` package's A* on the same occupancy and moves, medians:\n\n"
        + _table(head2, two)
    )


def arrest(r: dict) -> str:
    rows = []
    for x in r["runs"]:
        gap = x.get("max_contact_gap_at_arrest_m")
        hold = x.get("hold_displacement_m")
        at = x.get("arrest_time_s")
        rows.append([
            f"`{x['name']}`",
            " or ".join(f"`{e}`" for e in x["expect"]),
            f"`{x['outcome']}`" + ("" if x["as_expected"] else " (**not as expected**)"),
            f"{at:.1f} s" if at is not None else "-",
            f"{hold * 1e3:.1f} mm" if hold is not None else "-",
            f"{gap * 1e2:.1f} cm" if gap is not None else "-",
            str(x.get("wall_replans") if x.get("wall_replans") is not None else "-"),
            f"{x['wall_s']:.0f} s",
        ])  # fmt: skip
    head = ["scenario", "expected", "outcome", "arrest at (sim)", "hold displacement",
            "largest contact gap at the arrest", "wall re-plans", "wall time"]  # fmt: skip
    h = r["hold_displacement_m"]
    arrests = sum(x["outcome"] == "arrest" for x in r["runs"])
    held = (
        f"Hold displacement from truth over the {h['n']} arrests: median "
        f"{h['median'] * 1e3:.1f} mm, max {h['max'] * 1e3:.1f} mm (goal < 5 cm: "
        f"{_met(h['max'] is not None and h['max'] < 0.05)})."
        if h["n"]
        else "No arrest: no hold displacement."
    )
    return (
        f"The seeded arrest suite in pybullet, the object alive through the hold (walls, "
        f"corners, fast, evasive, concave), default rules: **{r['as_expected']} of "
        f"{r['total']} runs end as their test expects** ({arrests} arrests)."
        f" {held} Load {r['load_avg_1m']:.1f} at the end.\n\n" + _table(head, rows)
    )


def arrest_filter(r: dict) -> str:
    """The arrest suite with the safety filter on and off (Sharma's collision-free claim)."""

    def cm(x: float | None) -> str:
        if x is None:
            return "-"
        return f"{x * 1e6:.0f} µm (touching)" if x < 0 else f"{x * 1e2:.1f} cm"

    rows = []
    for x in r["runs"]:
        a, b = x["on"], x["off"]
        rows.append([
            f"`{x['name']}`", f"`{a['outcome']}`", cm(a["min_clearance_m"]),
            f"`{b['outcome']}`", cm(b["min_clearance_m"]), cm(b["object_min_clearance_m"]),
            "**yes**" if b["collision"] else "no",
        ])  # fmt: skip
    head = ["scenario", "filter on: outcome", "robots' closest", "filter off: outcome",
            "robots' closest", "closest to the object", "robots touched (off)"]  # fmt: skip
    n = len(r["runs"])
    holds = r["collisions_off"] == 0
    return (
        f"The arrest suite ({n} runs) twice in one process, on the same scenarios: the safety "
        "filter on, then bypassed (every robot's velocity as the approach plans it). The "
        "closest approaches are from the world's truth (a negative gap: robots touching). "
        f"Robots touched in **{r['collisions_off']} of {n}** runs with the filter off "
        f"({r['collisions_on']} with it on); arrests {r['arrests_off']} off, {r['arrests_on']} "
        f"on. Sharma et al.'s claim that the projective paths are collision-free without a "
        f"filter {'holds on this suite' if holds else '**does not hold** on this suite'}. "
        f"Load {r['load_avg_1m']:.1f} at the start, {r['load_avg_1m_end']:.1f} at the end.\n\n"
        + _table(head, rows)
    )


def arrest_edge(r: dict) -> str:
    """The speed edge (``bench/arrest.py --no-suite``): per speed and approach rules, the seeds
    arrested in open space with a Wilson interval, the median arrest time, the paired count."""
    e = r["speed_edge"]
    variants = list(e["variants"])
    speeds = [x["speed"] for x in e["variants"][variants[0]]["speeds"]]
    rows = []
    for i, v in enumerate(speeds):
        row = [f"{v:.2f} m/s"]
        for name in variants:
            x = e["variants"][name]["speeds"][i]
            lo, hi = x["wilson95"]
            times = sorted(
                run["t_s"]
                for key, run in e["variants"][name]["runs"].items()
                if key.startswith(f"{v:.2f}/") and run["arrest"] and run["t_s"] is not None
            )
            med = (
                times[len(times) // 2]
                if len(times) % 2
                else ((times[len(times) // 2 - 1] + times[len(times) // 2]) / 2 if times else None)
            )
            row += [
                f"{x['arrested']}/{x['runs']} ({lo:.2f}–{hi:.2f})",
                f"{med:.1f} s" if med is not None else "-",
            ]
        rows.append(row)
    head = ["object speed"]
    label = {
        "baseline": '`"classic"`, no braces',
        "new": '`"oncoming"`, no braces',
        "brace": "braces (the default)",
    }
    for name in variants:
        head += [f"{label.get(name, name)}: arrested (Wilson 95 %)", "median arrest (sim)"]

    def full(n: str) -> str:
        at = [x["speed"] for x in e["variants"][n]["speeds"] if x["arrested"] == x["runs"]]
        return (
            "every seed at " + ", ".join(f"{v:.2f}" for v in at) + " m/s"
            if at
            else "no speed of this run on every seed"
        )

    edges = "; ".join(f"{label.get(n, n)}: {full(n)}" for n in variants)
    paired = ""
    if "paired" in e:
        p, (a, b) = e["paired"], variants[:2]
        only_a, only_b = p.get(f"{a}_only", 0), p.get(f"{b}_only", 0)
        pv = mcnemar(only_a, only_b)
        paired = (
            f" Paired on the same seeds: {only_b} arrested by {label.get(b, b)} only, "
            f"{only_a} by {label.get(a, a)} only, {p['both']} by both"
            + (f" (McNemar's exact p = {pv:.2g})." if pv is not None else ".")
        )
    top = max(speeds)
    reached = any(
        x["speed"] >= 0.45 and x["arrested"] == x["runs"]
        for n in variants
        for x in e["variants"][n]["speeds"]
    )
    goal = f" Goal (every seed at 0.45 m/s): {_met(reached)}." if top >= 0.45 else ""
    return (
        f"Six omni robots of 0.5 m/s, {e['seeds']} seeded straight lines per speed in open "
        "space; an arrest counts only with no wall re-plan and the object never within 5 cm of "
        f"a wall (truth). Edge: {edges}.{paired}{goal} Load {r['load_avg_1m']:.1f} at the end "
        "(dry runs in lockstep: the outcomes do not depend on it).\n\n" + _table(head, rows)
    )


_SAME = "the same in every run: the dry run is lockstep"


def waits(r: dict) -> str:
    run, route, cap = r["run"], r["route"], r["capture"]

    def goal(x: dict, unit_goal: str) -> str:
        return f"{unit_goal}: **{'met' if x['goal_met'] else 'not met'}**"

    rows = [
        ["`make run` (`fleet run --config fleet.toml`, the whole process)",
         f"{run['wall_s_median']:.1f} s" if run["wall_s_median"] is not None else "-",
         f"{run['sim_time_s_median']:.0f} s of sim time"
         if run["sim_time_s_median"] is not None else "-",
         goal(run, f"<= {run['goal_s']:g} s"), str(run["failed"])],
        ["`fleet plan route --config fleet.toml` (128² × 36), the plan",
         f"{route['seconds_median']:.2f} s" if route["seconds_median"] is not None else "-",
         f"{route['wall_s_median']:.1f} s with the process",
         goal(route, f"< {route['goal_s']:g} s"), str(route["failed"])],
        ["`fleet plan capture --config fleet.toml`, the GA",
         f"{cap['seconds_median']:.2f} s" if cap["seconds_median"] is not None else "-",
         f"{cap['wall_s_median']:.1f} s with the process", "", str(cap["failed"])],
    ]  # fmt: skip
    head = ["what the user runs", "median", "beside it", "goal", "failed runs"]
    load = r["load_avg_1m"]
    outcome = ""
    first = (run.get("runs") or [{}])[0]
    if first.get("goal_error_deg") is not None:  # (rows from before this field: no outcome)
        same = all(
            x.get("goal_error_m") == first["goal_error_m"] and x.get("status") == first["status"]
            for x in run["runs"]
        )
        outcome = (
            f"\n\nThe job's outcome ({_SAME if same else 'the runs differ: see the row'}): "
            f"`{first['status']}`, {first['goal_error_m']:.3f} m / {first['goal_error_deg']:.1f}° "
            f"from the goal after {first['transport_time_s']:.1f} s of transport, arrested at "
            f"{first['arrest_time_s']:.1f} s, {first['rearrangements']} re-arrangements, "
            f"{first['relocations']} relocations, {first['missed_ticks']} missed ticks, "
            f"{first['watchdog_stops']} watchdog stops, robots at least "
            f"{first['min_clearance_m']:.4f} m apart; safety verdict "
            f"{'clean' if not first['verdict'] else first['verdict']}."
        )
    return (
        f"What a newcomer waits for, each in a process of its own, {r['repeats']} times "
        f"interleaved (medians). Load average {load[0]:.1f} at the start, {load[1]:.1f} at "
        "the end.\n\n" + _table(head, rows) + outcome
    )


def estop(r: dict) -> str:
    cases = [
        ("alive", "the daemon alive"),
        ("hung", "the daemon hung (SIGSTOP)"),
        ("dead", "the daemon dead (killed)"),
        ("no_hub_hung", "no `fleet hub` (the daemon's own), the daemon hung"),
    ]
    rows = [
        [what, f"{r[k]['elapsed_median_ms']:.0f} ms", f"{r[k]['elapsed_max_ms']:.0f} ms",
         f"{r[k]['resume_elapsed_median_ms']:.0f} ms", f"{r[k]['command_wall_median_s']:.2f} s",
         str(r[k]["tries"])]
        for k, what in cases
        if k in r
    ]  # fmt: skip
    head = ["case", "e-stop to every agent engaged, median", "worst", "`fleet resume`, median",
            "the whole `fleet estop` command, median", "tries"]  # fmt: skip
    return (
        "`fleet estop` from its publication to the last agent's confirmation, as the tool "
        "reports it (`elapsed_s`): a hub, a daemon holding three sim agents still (ideal "
        "backend), loopback; `fleet resume` after each (it first asks the latch's holders for "
        "its epoch). The whole command includes Python's start-up. Load average "
        f"{r['loadavg'][0]:.1f} at the end.\n\n" + _table(head, rows)
    )


SITL_FRAMES = {
    "rover": "ackermann car (`--model rover`)",
    "rover-skid": "skid-steer (`rover-skid`)",
    "rover-omni3mecanum": "3-wheel mecanum omni (`rover-omni3mecanum`), driven as `diff`",
}


def sitl(r: dict) -> str:
    """ArduRover SITL stop times from 0.4 m/s, one frame per row (``bench/sitl.py``)."""
    settings = [
        ("zero_then_hold_at_rest", '`stop_hold = "at_rest"` (the default)'),
        ("zero_only", '`"off"`: zero setpoint only, GUIDED brakes'),
        ("zero_and_hold", '`"now"`: zero setpoint and HOLD at once'),
    ]
    rows = []
    for key, what in settings:
        for how in ("estop", "watchdog"):
            t = r[f"{how}_{key}_s"]
            rows.append([what, "e-stop" if how == "estop" else "watchdog",
                         f"{t['median']:.2f} s", f"{t['min']:.2f}–{t['max']:.2f} s"])  # fmt: skip
    best = r["estop_zero_then_hold_at_rest_s"]["median"]
    goal = 1.0
    return (
        f"{SITL_FRAMES.get(r['frame'], r['frame'])}, stock parameters: connected in "
        f"{r['connect_s']:.0f} s (the firmware's position estimate included) at "
        f"{r['telemetry_hz']:.0f} Hz granted. From {r['speed_mps']} m/s to the firmware's "
        f"first LOCAL_POSITION_NED under {r['stopped_below_mps']} m/s, {r['tries']} tries "
        f"each. Goal under {goal:.0f} s with the default: {_met(best < goal)} "
        f"({best:.2f} s).\n\n" + _table(["stop setting", "stopped by", "median", "min–max"], rows)
    )


def _claims(sec: dict, label: str) -> list[str]:
    """What each pairwise test of a set says at 5 % after Holm's adjustment."""
    out = []
    for pair, p in sec["paired"].items():
        a, b = pair.split("_vs_")
        w = p["success"]
        said = []
        ps = w.get("p_holm")
        if ps is not None and ps < 0.05:
            better = a if w["only_a_delivered"] > w["only_b_delivered"] else b
            said.append(f"`{better}` delivers more (Holm p {ps:.2g})")
        else:
            said.append("no difference in deliveries shown" + (f" (Holm p {ps:.2g})" if ps else ""))
        for key, name in (("transport_time_s", "time"), ("impulse_ns", "contact impulse")):
            q = p[key]
            pq = q.get("p_holm")
            if q["pairs"] and pq is not None and pq < 0.05:
                said.append(
                    f"{name} ratio {q['median_ratio_a_over_b']} over {q['pairs']} pairs (Holm p "
                    f"{pq:.2g}): shown"
                )
            else:
                said.append(f"{name}: no difference shown over {q['pairs']} pairs both delivered")
        out.append(f"- {label}, `{a}` vs `{b}`: " + "; ".join(said) + ".")
    return out


def _sharma_criterion(r: dict) -> str:
    """What the row's "Sharma" column measured: the centroid at its first arrival (rows with
    ``goal_centroid_reached_s``), or, in older rows, the polygon frame's origin at the end."""
    runs = r.get("closed_loop_runs") or r.get("robustness_runs") or []
    if runs and "goal_centroid_reached_s" in runs[0]:
        return (
            "the CG, the object's centroid, within the position tolerance of the goal's at its "
            "first arrival, heading free, clean verdict"
        )
    return (
        "in this row measured at the polygon frame's origin, not the CG, at the end of the "
        "run, heading free"
    )


def transport_compare(r: dict) -> str:
    from bench.transport_compare import table

    size = r["size"]
    claims = []
    for sec, label in (("closed_loop", "suite"), ("robustness", "robustness")):
        if sec in r:
            claims += _claims(r[sec], label)
    fails = []
    for sec, label in (("closed_loop", "suite"), ("robustness", "robustness")):
        for st, x in r.get(sec, {}).items():
            if st not in ("paired", "invalid_runs") and x["failures"]:
                fails.append(f"{label} `{st}`: " + ", ".join(f"`{f}`" for f in x["failures"]))
    return (
        f"The suite: {size['scenarios']} drawn scenarios of bench/transport_loop.py's seeded "
        f"suite (never tuned on) × {size['seeds']} seeds × {len(size['strategies'])} strategies, "
        f"each a whole `fleet run --mission transport` in lockstep on {size['backend']}; "
        + (
            f"the robustness set: {size['sweep_runs_per_strategy']} runs per strategy with "
            "Yamashita's robot motion errors and the object's mass, floor friction and centre "
            "of mass off. "
            if size["sweep_runs_per_strategy"]
            else "no robustness set in this row. "
        )
        + "Success on our criterion (delivered within the position and heading tolerance, clean "
        f"verdict) and on Sharma's ({_sharma_criterion(r)}), with "
        "95 % Wilson intervals; medians over the runs a strategy delivered with bootstrap "
        "intervals; paired: McNemar's exact test on success, Wilcoxon on time and impulse, "
        "Holm across the table.\n\n"
        + table(r)
        + "\n\nWhich differences hold at 5 % (after Holm):\n\n"
        + "\n".join(claims)
        + ("\n\nFailure reasons: " + "; ".join(fails) + "." if fails else "")
    )


def transport_varied(r: dict) -> str:
    """The varied suite (issue 34, item 1): the comparison table, then per shape what Eq. 5
    and the serpentine did."""
    from bench.transport_compare import table

    runs = r["varied_runs"]
    groups = {g["scenario"]: g for g in r["eq5_groups"]}
    strategies = r["size"]["strategies"]
    rows = []
    for sc in sorted({x["scenario"] for x in runs}, key=lambda n: int(n.split("-")[1])):
        mine = {x["strategy"]: x for x in runs if x["scenario"] == sc}
        g = groups[sc]
        any_run = next(iter(mine.values()))
        serp = mine.get("serpentine", {})
        serp_counts = (
            f"{serp['serpentine_two_group_plans']}/{serp['serpentine_plans']}, "
            f"{serp['serpentine_switches']}"
            if serp.get("serpentine_plans") is not None
            else "–"
        )
        cells = []
        for s in strategies:
            x = mine.get(s)
            if x is None:
                cells.append("–")
            else:
                mark = "✓" if x["success"] else f"✗ `{x['reason'] or 'not_delivered'}`"
                paper = " (CG ✓)" if x["success_paper"] and not x["success"] else ""
                cells.append(mark + paper)
        rows.append(
            [
                f"`{sc}`",
                f"{g['robots']} ({any_run['kinds'].count('d')} diff)",
                "yes" if any_run["heading_goal"] else "free",
                f"{g['group_sizes'][0]} + {g['group_sizes'][1]}",
                *cells,
                serp_counts,
            ]
        )
    head = ["scenario", "robots", "goal heading", "Eq. 5 groups", *[f"`{s}`" for s in strategies],
            "serpentine: two-group plans, switches"]  # fmt: skip
    two = sum(g["two_groups"] for g in r["eq5_groups"])
    shapes_two = sorted({g["shape"] for g in r["eq5_groups"] if g["two_groups"]})
    shapes_one = sorted({g["shape"] for g in r["eq5_groups"] if not g["two_groups"]})
    claims = _claims(r["varied"], "varied")
    mu = r["size"].get("contact_friction")
    friction = (
        f"Contact friction {mu:g} between robots and object, in the world and in the "
        "contact-force LP's friction cones (every other row: 0). "
        if mu
        else ""
    )
    return (
        friction + f"The varied suite: {r['size']['varied_scenarios']} scenarios drawn by "
        "`bench/transport_loop.py`'s `draw_varied_suite` (seed 3141, never tuned on): eight "
        "shapes in turn (crate, square, long crate, bar, L, T, diamond, trapezoid), 4-8 robots "
        "omni or mixed, a straight goal 2.5-3.5 m away in any direction with the start's "
        "heading, a quarter turn, or no heading target (heading tolerance 180°); one run per "
        "scenario and strategy in lockstep on pybullet. Eq. 5's set for the straight line "
        f"splits into Sharma's two groups in {two} of {len(r['eq5_groups'])} scenarios (shapes "
        f"where it did: {', '.join(shapes_two)}; where it did not at least once: "
        f"{', '.join(shapes_one) or 'none'}).\n\n"
        + table(r)
        + "\n\n"
        + _table(head, rows)
        + "\n\nWhich differences hold at 5 % (after Holm):\n\n"
        + "\n".join(claims)
    )


#: Yamashita's conditions by the strategy's suffix (bench/transport_compare.py ERROR_MODELS)
CONDITIONS = {
    "": "1: without errors",
    "errors": "2: consider errors",
    "pose": "2, motion error only",
}


def transport_errors(r: dict) -> str:
    """Yamashita's Table 1 (issue 34, item 5): plans that ignore the errors (condition 1)
    against plans that allow for them (condition 2), on the same seeds and worlds."""
    from bench.transport_compare import YAMASHITA_ERRORS, _p, table

    sets = [(sec, label) for sec, label in (("robustness", "robustness"), ("varied", "varied"))
            if sec in r]  # fmt: skip
    rows, claims = [], []
    for sec, label in sets:
        for st, x in r[sec].items():
            if st in ("paired", "invalid_runs"):
                continue
            share = x["push_contact_share"]
            mine = [y for y in r[f"{sec}_runs"] if y["strategy"] == st and y.get("valid", True)]
            rows.append(
                [
                    label,
                    CONDITIONS[st.partition("+")[2]] + f" (`{st}`)",
                    f"{x['success']['k']}/{x['runs']}",
                    str(x["collisions"]),
                    str(sum(y["rearrangements"] or 0 for y in mine)),
                    f"{x['push_contact_losses']} in {x['runs_with_contact_losses']} runs",
                    "–" if share["median"] is None else f"{100 * share['median']:.0f} %",
                    ", ".join(f"`{f}`" for f in x["failures"]) or "–",
                ]
            )
        said = _claims(r[sec], label)
        for i, (pair, p) in enumerate(r[sec]["paired"].items()):
            a, b = pair.split("_vs_")
            q, c = p["push_contact_losses"], p["collision"]
            lost = (
                f"contacts lost: `{a}` fewer in {q['a_lower']} of {q['pairs']} pairs, more in "
                f"{q['a_higher']} (Wilcoxon p {_p(q['wilcoxon_p'])}, Holm {_p(q['p_holm'])})"
            )
            hit = (
                f"collisions: only `{a}` in {c['only_a']}, only `{b}` in {c['only_b']} (McNemar "
                f"p {_p(c['mcnemar_p'])}, Holm {_p(c['p_holm'])})"
            )
            said[i] = f"{said[i].rstrip('.')}; {lost}; {hit}."
        claims += said
    head = ["set", "condition", "delivered", "runs with a collision", "re-arrangements",
            "contacts lost",
            "pushers touching (median share)", "failures"]  # fmt: skip
    model = ", ".join(f"{k} {v}" for k, v in YAMASHITA_ERRORS.items())
    return (
        "Condition 1 plans as if the world were as configured (`transport.errors` all 0, the "
        "default); condition 2 (`sa+errors`) plans with Yamashita et al.'s error model "
        f"(`transport.errors`: {model}); `sa+pose` with its motion error alone (`position`). "
        "All run on the same seeds in the same worlds, which "
        "are off as Table 1 has it: every robot's pose reports off its true pose by a fixed "
        "offset within ±0.04 m, ±0.01 m, the object's mass and floor friction ×U(0.9, 1.1) and "
        "its centre of mass within ±1 cm (the controller is told the nominal object). The sets: "
        f"the robustness set ({r['size']['sweep_runs_per_strategy']} runs of one crate on an "
        f"open floor) and the varied suite ({r['size']['varied_scenarios']} scenarios, its "
        "worlds off the same way). *Contacts lost*: a robot the plan has pushing off the object "
        "for half a second (the world's contact forces); *pushers touching*: the share of the "
        "pushers' ticks they touched it.\n\n"
        + table(r)
        + "\n\n"
        + _table(head, rows)
        + "\n\nWhich differences hold at 5 % (after Holm):\n\n"
        + "\n".join(claims)
    )


def error_model(r: dict) -> str:
    """What planning with the error model costs per local plan (issue 34, item 5)."""

    def cell(c: dict) -> str:
        return f"{c['plan_ms_median']:.1f} ms (max {c['plan_ms_max']:.0f})"

    rows = [
        [str(x["robots"]), cell(x["condition_1"]), cell(x["condition_2"]), f"{x['time_ratio']:.2f}"]
        for x in r["plans"]
    ]
    load = r["load_average"][0], r["load_average_end"][0]
    return (
        f"One `sa` plan with the default settings on the seeded push cases ({r['seeds']} seeds "
        "per robot count), without the error model (condition 1) and with Yamashita's "
        "(condition 2), in one process one after the other; the ratio is of the medians. Load "
        f"average {load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n"
        + _table(["robots", "condition 1", "condition 2", "ratio"], rows)
    )


def brace(r: dict) -> str:
    """What a look for braces costs (issue 34, item 10)."""
    load = r["load_average"][0], r["load_average_end"][0]
    rows = [
        ["look for braces (`braced_capture`)", f"{r['brace_look_ms_median']:.0f} ms",
         f"{r['brace_look_ms_max']:.0f} ms"],
        ["capture plan at the start (`plan_capture_set`)", f"{r['capture_plan_ms_median']:.0f} ms",
         f"{r['capture_plan_ms_max']:.0f} ms"],
    ]  # fmt: skip
    return (
        f"The speed edge's {r['seeds']} seeded cases at {r['speed_m_s']:.2f} m/s at first "
        "sight, each timed in one process against the capture plan the job makes at the start "
        f"(both off the tick, jobs of kind `capture`, budget 0.5 s): a look costs "
        f"{r['ratio_look_to_plan']:.2f} times a capture plan (medians); it found braces on "
        f"{r['braced_seeds']} of {r['seeds']} seeds at first sight (the others look again "
        f"every 0.5 s). Load average {load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n"
        + _table(["job", "median", "largest"], rows)
    )


def serpentine_traces(r: dict) -> str:
    """Why the serpentine stalls, read from its logs (issue 34, item 2)."""
    rows = []
    for x in r["runs"]:
        w = x.get("stall")
        rows.append(
            [
                f"`{x['scenario']}`",
                str(x["robots"]),
                f"`{x['outcome']}`",
                f"{x['first_lp_feasible']}/{x['plans']}",
                str(x["two_groups"]),
                f"{x['still']}: {x['still_pushing']} + {x['still'] - x['still_pushing']}",
                f"{x['planned_toward_m']:.2f} / {x['moved_toward_m']:.2f} m",
                f"{x['planned_turn_deg']:.0f} / {x['turned_deg']:.0f}°",
                f"{x['turn_deg']:.0f}°",
                "–"
                if w is None
                else f"{w['plans']}: {w['still_pushing']} + {w['still'] - w['still_pushing']}; "
                f"{w['planned_toward_m']:.2f} / "
                f"{w['moved_toward_m']:.2f} m; {w['planned_turn_deg']:.0f} / "
                f"{w['turned_deg']:.0f}°",
            ]
        )
    head = ["scenario", "robots", "outcome", "first interval's LP feasible", "two groups manned",
            "plans moving nothing: at the subgoal + group empty",
            "toward the goal: planned / true",
            "turned: planned / true", "largest turn from the start",
            "last stall window: plans: at the subgoal + group empty; toward the goal; "
            "turned"]  # fmt: skip
    su = r["summary"]
    a, w = su["all"], su["stall_windows"]
    return (
        f"Each of the varied suite's {r['size']['scenarios']} scenarios run once with "
        '`transport.strategy = "serpentine"` in lockstep on pybullet, its log read back: per '
        "local plan, whether the contact-force LP of its first interval has an answer, whether "
        "both of Sharma's groups are manned, and what the first interval planned against what "
        "the object truly did over it (the world's truth): distance gained toward the goal's "
        "centroid, and turn. For a failed run, the same over the last `transport.stall_timeout` "
        f"before the failure. Over all {a['plans']} plans: the first interval's LP feasible in "
        f"{a['first_lp_feasible']}, both groups manned in {a['two_groups']}, the first "
        f"interval moving nothing in {a['still']} ({a['still_pushing']} with the active group "
        "in contact: the twist is zero because the object's match on the route is at the "
        f"subgoal already; {a['still'] - a['still_pushing']} with no robot of the active group "
        "in contact); toward the goal "
        f"planned {a['planned_toward_m']:.1f} m, truly {a['moved_toward_m']:.1f} m; turned "
        f"planned {a['planned_turn_deg']:.0f}°, truly {a['turned_deg']:.0f}°. Over the "
        f"{w['runs']} failed runs' last windows ({w['plans']} plans): LP feasible in "
        f"{w['first_lp_feasible']}, moving nothing in {w['still']} ({w['still_pushing']} at the "
        f"subgoal, {w['still'] - w['still_pushing']} with the group empty), toward the goal "
        f"planned {w['planned_toward_m']:.2f} m, truly "
        f"{w['moved_toward_m']:.2f} m; turned planned {w['planned_turn_deg']:.0f}°, truly "
        f"{w['turned_deg']:.0f}°.\n\n" + _table(head, rows)
    )


def sa_random_starts(r: dict) -> str:
    """Vass's claim (issue 34, item 7): SA against downhill from the same random starts."""
    rows = []
    for name, s in r["settings"].items():
        rows.append(
            [
                f"`{name}`",
                str(s["pairs"]),
                f"{s['sa_lower']} / {s['downhill_lower']} / {s['ties']}",
                f"{s['sign_test_p']:.2g} (Holm {s['sign_test_p_holm']:.2g})",
                f"{s['wilcoxon_p']:.2g}",
                f"{s['median_energy']['sa']:.1f} / {s['median_energy']['downhill']:.1f}",
                f"{s['plans_with_infeasible_intervals']['sa']} / "
                f"{s['plans_with_infeasible_intervals']['downhill']}",
                f"{s['median_plan_ms']['sa']:.0f} / {s['median_plan_ms']['downhill']:.0f} ms",
                f"**{s['verdict']}**",
            ]
        )
    head = ["setting", "pairs", "SA lower / downhill lower / equal", "sign test p",
            "Wilcoxon p", "median energy SA / downhill", "plans still infeasible somewhere",
            "plan time", "favours"]  # fmt: skip
    shapes = ", ".join(f"{k} {v}" for k, v in r["shapes"].items())
    return (
        f"Each pair: one planning problem and one random start matrix (`initial_actions = "
        f'"random"`), planned by `sa` and by `downhill` from that same start; the lower energy '
        f"wins. {sum(r['shapes'].values())} solvable problems drawn by seed {r['seed']} "
        f"({shapes}; {r['rejected']} drawn problems that no plan from the LP's start could push "
        "without an infeasible interval or a collision were drawn again). `default`: 100 "
        "iterations, T0 0.3, cooling 0.95; `long`: 300 iterations, T0 1.0, cooling 0.985. The "
        "rule, fixed before the run: a setting favours a planner when it wins more pairs and "
        "the Holm-adjusted exact sign test gives p < 0.05.\n\n" + _table(head, rows)
    )


def heavy(r: dict) -> str:
    """Heavy loads (issue 34, item 9): the route along the ways the fleet can push."""
    rows = []
    for name, c in r["cases"].items():
        p, rp, rn = c["pushability"], c["route"]["plain"], c["route"]["pushed"]
        loop = c.get("closed_loop")
        run = "–"
        if loop:
            run = (
                f"{'delivered' if loop['status'] == 'ok' else loop['reason']}, "
                f"{loop['transport_time_s']:.0f} s, {loop['rearrangements']} re-arrangements, "
                f"{loop['goal_error_m']:.2f} m / {loop['goal_error_deg']:.1f}°"
            )
        route = (
            "too heavy at any heading"
            if rn["too_heavy"]
            else f"{rn['length_m']:.2f} m, {rn['rotation_deg']:.0f}° turned, "
            f"{rn['manipulations']} re-arrangements"
        )
        rows.append(
            [
                f"`{name}`",
                f"{c['need_n']:.1f} N of {c['fleet_n']:.0f} N",
                f"{100 * p['best_share']:.0f} % ({p['best_robots']} robots)",
                f"{100 * p['bound_share']:.0f} %",
                f"{p['pushable_buckets']} of 72",
                f"{rp['length_m']:.2f} m, {rp['rotation_deg']:.0f}°",
                route,
                f"{rn['first_plan_s']:.1f} s / {rn['replan_s'] * 1e3:.0f} ms "
                f"(plain {rp['plan_s'] * 1e3:.0f} ms)",
                run,
            ]
        )
    head = ["object", "floor friction of the fleet's force", "best set",
            "LP bound (every contact)", "directions it can push", "route without the limit",
            "route along pushable ways", "first plan / re-plan", "pybullet run"]  # fmt: skip
    return (
        "Per object: the best share of the floor friction a set of contacts the transport "
        "would ask for produces (every robot at the weakest's force), over 72 directions in the "
        "object's frame; the LP bound over every candidate contact (under 100 %: no set of the "
        "whole fleet moves it, at any heading); the directions that can be pushed with 10° of "
        "heading slack; the route without and with the limit, and what the limit costs the "
        "first plan (the 72 directions learned) and a re-plan.\n\n" + _table(head, rows)
    )


def _delivered(lab: dict) -> bool:
    """A lab run that exited 0 with a DELIVERED verdict (a lab of before the verdict decided
    the exit could exit 0 on a verdict that failed)."""
    verdict = (lab.get("outcome") or {}).get("verdict") or ""
    return lab.get("exit") == 0 and verdict.startswith("DELIVERED")


def _verdict_m(verdict: str) -> str:
    m = re.match(r"DELIVERED ([\d.]+ m)", verdict)
    return m.group(1) if m else "-"


def job(r: dict) -> str:
    rows = []
    for x in r["runs"]:
        d = x.get("dry_run")
        if d:
            done = d.get("status") == "ok"
            rows.append(
                [
                    str(x["robots"]),
                    "dry run (`fleet run`, lockstep)",
                    "**delivered**" if done else f"**{d.get('status')}** ({d.get('reason')})",
                    f"{d['wall_s']:.0f} s wall, {d['sim_time_s']:.0f} s sim",
                    f"{d['goal_error_m']:.3f} m" if done else "-",
                    f"{d['missed_ticks']} missed",
                    str(d.get("watchdog_stops", "-")),
                ]
            )
        for lab in x.get("labs", []):
            o = lab.get("outcome") or {}
            ok = _delivered(lab)
            ticks = (
                (
                    f"{lab['late_ticks']} late of {lab['ticks']}; p50 {lab['tick_p50_ms']:.0f}"
                    f" / p99 {lab['tick_p99_ms']:.0f} ms"
                )
                if "ticks" in lab
                else "-"
            )
            rows.append(
                [
                    str(x["robots"]),
                    "lab in real time (`fleet up`, `resume`, `down --wait`)",
                    "**delivered**" if ok else f"**{o.get('verdict', 'failed')}**",
                    f"{lab['job_wall_s']:.0f} s from the resume; up in {lab['up_s']:.0f} s",
                    _verdict_m(o.get("verdict", "")),
                    ticks,
                    str(lab.get("watchdog_stops_while_driven", "-")),
                ]
            )
    # fmt: skip
    head = ["robots", "how", "outcome", "time", "goal error", "ticks",
            "watchdog stops while driven"]  # fmt: skip
    load = r["load_avg_1m"]
    if r.get("shipped"):
        labs = [lab for x in r["runs"] for lab in x.get("labs", [])]
        k = sum(_delivered(lab) for lab in labs)
        lo, hi = wilson(k, len(labs))
        why: dict[str, int] = {}
        for lab in labs:
            if not _delivered(lab):
                verdict = (lab.get("outcome") or {}).get("verdict") or ""
                said = re.match(r"FAILED (\w+)", verdict)
                reason = (lab.get("outcome") or {}).get("reason") or (said and said[1]) or "none"
                why[reason] = why.get(reason, 0) + 1
        fails = ", ".join(f"`{w}` {c}" for w, c in sorted(why.items())) or "none"
        wait = r.get("resume_delay_s") or 0.0
        delay = f"{wait:g} s after the lab is up" if wait else "at once"
        return (
            "The README's lab block, `lab.toml` as shipped (fleet.toml's job: six robots, three "
            "of them differential), each run a fresh `fleet up --detach`, `fleet resume` "
            f"{delay}, `fleet down --wait`, on free loopback ports, in real time: "
            f"**delivered in {k} of {len(labs)} runs** (95 % Wilson interval "
            f"{lo:.2f}-{hi:.2f}); the failures by reason: {fails}. Load average "
            f"{load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n" + _table(head, rows)
        )
    return (
        "`fleet.toml`'s job with the fleet in three staggered rows along the south wall (every "
        "third robot differential), run as a user runs it. Load average "
        f"{load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n" + _table(head, rows)
    )


def transport(r: dict) -> str:
    rows = []
    for name, x in r["planners"].items():
        sa, dh, sp, warm = x["sa"], x["downhill"], x["serpentine"], x["sa_warm_ticks"]
        rows.append([f"`{name}`", str(x["robots"]),
                     f"{sa['median_ms']:.1f} / {sa['p95_ms']:.1f} ms",
                     f"{warm['median_ms']:.1f} ms",
                     f"{dh['median_ms']:.1f} ms", f"{sp['median_ms']:.1f} ms",
                     f"{sa['energy_median']:.1f}", f"{dh['energy_median']:.1f}",
                     f"{sp['energy_median']:.1f}"])  # fmt: skip
    head = ["scenario", "robots", "sa median / p95", "sa re-planning each tick", "downhill",
            "serpentine", "energy: sa", "downhill", "serpentine"]  # fmt: skip
    g = r["goals"]
    cmp = ", ".join(
        f"{it} iterations: lower on {v['sa_lower']}, equal on {v['equal']}, higher on "
        f"{v['sa_higher']}"
        for it, v in r["sa_vs_downhill"].items()
    )
    load = r["load_average"][0], r["load_average_end"][0]
    return (
        "One local plan (`controller.planning.transport.plan_local`, the defaults: 100 "
        "iterations over 8 intervals) on the bench's seeded planning scenarios, wall-clock "
        "medians. Energy: lower is better; 800 is 8 intervals with no force equilibrium "
        "(`k_equilibrium` 100 each) and no progress, i.e. a plan that cannot move the object. "
        "The goal, one SA plan at 8 robots under 50 ms (the median over the 8-robot "
        f"scenarios): {g['sa_plan_8_robots_median_ms']:.1f} ms from scratch, "
        f"{g['sa_plan_8_robots_warm_tick_median_ms']:.1f} ms re-planning each tick, "
        f"**{'met' if g['sa_goal_50ms_met'] else 'not met'}**. SA against its downhill "
        f"ablation, same seeds, over the (scenario, seed) pairs: {cmp}. Load average "
        f"{load[0]:.1f} at the start, {load[1]:.1f} at the end.\n\n" + _table(head, rows)
    )


def transport_loop(r: dict) -> str:
    def num(v, fmt: str, unit: str = "") -> str:
        return "-" if v is None else f"{v:{fmt}}{unit}"

    rows = []
    for name, a in r["closed_loop"].items():
        done = sum(bool(x.get("transported")) for x in a["runs_detail"])
        rows.append(
            [
                f"`{name}`",
                f"**{done} of {a['runs']}**",
                num(a["transport_time_s"], ".1f", " s"),
                num(
                    a["lateral_deviation_rms_m"] and a["lateral_deviation_rms_m"] * 100,
                    ".1f",
                    " cm",
                ),
                num(
                    a["max_lateral_deviation_m"] and a["max_lateral_deviation_m"] * 100,
                    ".1f",
                    " cm",
                ),
                num(a["impulse_ns"], ".0f", " N·s"),
                num(a["rearrangements"], ".1f"),
                num(a.get("plan_tick_ms_p90_median"), ".2f", " ms"),
                str(a["missed_ticks_max"]),
            ]
        )
    # fmt: skip
    head = [
        "strategy",
        "delivered",
        "transport time",
        "lateral deviation RMS",
        "max",
        "contact impulse",
        "re-arrangements",
        "the tick's plan stage, p90",
        "missed ticks (max)",
    ]
    # fmt: skip
    suite = "; ".join(
        f"{x['name']}: {x['shape']}, {'pillar' if x['pillar'] else 'open'}" for x in r["suite"]
    )
    text = (
        "Whole `fleet run --mission transport` runs in pybullet, lockstep (the robots already "
        "hold the object; judged from the world's truth), on the bench's seeded suite, never "
        f"used by the tests ({suite}). One run per scenario and strategy: no spread, so a "
        "difference of medians here is one seed's, not a comparison (the 180-run comparison "
        "below pairs 20 seeds per scenario). Medians over each strategy's delivered runs. "
    )
    pair = r.get("sa_vs_serpentine")
    if pair and not pair["both_delivered"]:
        text += "No scenario did both SA and serpentine deliver: no paired comparison. "
    elif pair:
        text += (
            f"SA against serpentine on the {pair['both_delivered']} scenarios both delivered "
            "(the fair count): impulse ratio "
            f"{num(pair['impulse_ns_ratio_paired_median'], '.2f')}, time ratio "
            f"{num(pair['transport_time_s_ratio_paired_median'], '.2f')}; the ratios of each "
            "one's medians over its own successes (the unfair count): "
            f"{num(pair['impulse_ns_ratio_of_medians'], '.2f')} and "
            f"{num(pair['transport_time_s_ratio_of_medians'], '.2f')}. "
        )
    load = r["load_average"][0], r["load_average_end"][0]
    return text + (
        f"Load average {load[0]:.1f} at the start, {load[1]:.1f} at the end (the outcomes do "
        "not depend on it; the plan times do).\n\n" + _table(head, rows)
    )


RENDER: dict[str, Callable[[dict], str]] = {
    "arrest": arrest,
    "arrest_edge_low": arrest_edge,
    "arrest_edge_high": arrest_edge,
    "arrest_edge_brace": arrest_edge,
    "brace": brace,
    "arrest_filter": arrest_filter,
    "approach": approach,
    "contact_lp": contact_lp,
    "estimation": estimation,
    "sim": sim,
    "bus": bus,
    "bus_flood": bus_flood,
    "command_burst": command_burst,
    "loop": loop,
    "mavlink": mavlink,
    "logs": logs,
    "route_tables": route_tables,
    "capture": capture,
    "capture_fresh": capture_fresh,
    "capture_paper_closure": capture_fresh,
    "route": route,
    "waits": waits,
    "job": job,
    "estop": estop,
    "sitl_car": sitl,
    "sitl_skid": sitl,
    "sitl_mecanum": sitl,
    "lab_job": job,
    "lab_job_late": job,
    "transport": transport,
    "transport_loop": transport_loop,
    "transport_compare": transport_compare,
    "transport_varied": transport_varied,
    "transport_varied_friction": transport_varied,
    "sa_random_starts": sa_random_starts,
    "transport_errors": transport_errors,
    "serpentine_traces": serpentine_traces,
    "error_model": error_model,
    "heavy": heavy,
}


def render(name: str) -> str:
    path = ROWS / f"{name}.json"
    if name not in RENDER:
        raise SystemExit(f"pages: no renderer for the block `{name}` (bench/pages.py RENDER)")
    if not path.is_file():
        return f"*No row yet: `python bench/record.py {name}` then `python bench/pages.py`.*\n"
    row = json.loads(path.read_text())
    return RENDER[name](row["result"]).rstrip() + "\n\n" + provenance(row) + "\n"


def rewrite(text: str) -> str:
    return BLOCK.sub(lambda m: m.group(1) + render(m.group("name")) + m.group(4), text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only say which pages are stale")
    ns = ap.parse_args()
    stale = []
    for page in sorted(PAGES.glob("*.md")):
        text = page.read_text()
        new = rewrite(text)
        if new != text:
            stale.append(page)
            if not ns.check:
                page.write_text(new)
    if ns.check and stale:
        names = ", ".join(str(p.relative_to(ROOT)) for p in stale)
        print(f"pages: not current with bench/rows: {names}; run python bench/pages.py")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
