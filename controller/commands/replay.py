"""``fleet replay F.mcap [--json] [--plots DIR] [--republish]``: a run's log, analysed.

Reads the MCAP log of a dry run, a daemon or ``fleet record`` (a file cut short by a crash is
read up to the cut) and prints metrics: per-robot pose and command rates, path lengths,
estimation error against ground truth (dry runs log it), minimum robot-robot clearance, the
deepest robot-object overlap, phases, the arrest, e-stops and lost links. ``--plots DIR`` writes
PNG figures; ``--republish`` plays the messages back on the config's zenoh bus with their
original spacing (``--speed``), without the command and e-stop keys unless
``--with-commands`` (a replay must not drive real robots).
"""

from __future__ import annotations

import sys
from pathlib import Path

from controller.commands import DEFAULT_CONFIG

NOT_REPLAYED = ("/cmd", "/estop", "/sim/clock", "/sim/done")


def add_arguments(parser, word: str) -> None:
    parser.add_argument("log", help="MCAP file of a run")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plots", default=None, help="write PNG figures into this directory")
    parser.add_argument(
        "--republish", action="store_true", help="publish the messages again on the bus"
    )
    parser.add_argument(
        "--speed", type=float, default=1.0, help="playback speed factor (0: no pacing)"
    )
    parser.add_argument(
        "--with-commands", action="store_true", help="also republish commands and e-stops"
    )
    parser.add_argument(
        "--config",
        default=None,
        help=f"zenoh settings for --republish (default: recorded config, else {DEFAULT_CONFIG})",
    )


def run(args) -> int:
    from controller.cli import emit_json
    from controller.replay.log import load_run, metrics_of
    from controller.viz import plot_run

    path = Path(args.log)
    if not path.is_file():
        print(f"fleet replay: {path}: no such file", file=sys.stderr)
        return 2
    if args.speed < 0:
        print("fleet replay: --speed: expected >= 0", file=sys.stderr)
        return 2
    try:
        run_log = load_run(path)
    except OSError as exc:
        print(f"fleet replay: {path}: {exc}", file=sys.stderr)
        return 2
    if not run_log.topics and not run_log.complete:
        print(f"fleet replay: {path}: not an MCAP log (or empty)", file=sys.stderr)
        return 2
    result = metrics_of(run_log)
    if args.plots:
        result["plots"] = [str(p) for p in plot_run(run_log, args.plots)]
    if args.republish:
        result["republished"] = _republish(args, run_log)
    if args.json:
        emit_json(result)
    else:
        _print(result)
    return 0


def _republish(args, run_log) -> int:
    from controller.config import load_config
    from controller.io.bus import Bus
    from controller.replay.republish import republish

    cfg = load_config(args.config) if args.config else run_log.config
    if cfg is None:
        cfg = load_config(DEFAULT_CONFIG)
    keys = sorted(k for k in run_log.topics if args.with_commands or not k.endswith(NOT_REPLAYED))
    print(f"fleet replay: republishing {len(keys)} keys on {cfg.zenoh.listen}", file=sys.stderr)
    with Bus(cfg.zenoh, cfg.fleet.name) as bus:
        return republish(args.log, bus, args.speed, keys)


def _print(r: dict) -> None:
    print(f"{r['log']}: {'complete' if r['complete'] else 'cut short (crash?)'}, {r['mode']}")
    print(
        f"  {r['messages']} messages over {r['duration_s']:.1f} s, {r['undecodable']} undecodable"
    )
    for rid, m in r["robots"].items():
        err = m["estimate_error"]
        e = f", estimate RMSE {err['rmse_m'] * 100:.1f} cm" if err else ""
        print(
            f"  {rid}: {m['poses']} poses ({m['pose_rate_hz']:.1f} Hz), {m['commands']} commands "
            f"({m['command_rate_hz']:.1f} Hz), path {m['path_length_m']:.2f} m{e}"
        )
    o = r["object"]
    print(f"  object: path {o['path_length_m']:.2f} m, final {o['final_pose']}")
    for p in r["phases"]:
        print(f"  phase {p['phase']} from t={p['t']:.2f}")
    for k in (
        "arrested",
        "arrest_time_s",
        "arrival_spread_s",
        "min_clearance_m",
        "max_object_penetration_m",
        "link_lost",
    ):
        print(f"  {k}: {r[k]}")
    for p in r.get("plots", []):
        print(f"  plot: {p}")
