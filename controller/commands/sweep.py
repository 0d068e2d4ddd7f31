"""``fleet sweep CONFIG... [--json] [--out-dir DIR] [--max-time S] [--backend B]``.

The dry run of every config in turn, each on a free loopback port picked automatically; one
summary line per run on stderr as it ends, then a table (``--json``: one object with ``runs``,
one row each: config, status, phase, reason, detail, sim and wall time, arrest time, minimum
clearance, verdict, log). Logs go to ``DIR/<n>-<config name>.mcap`` (default
``<log.dir>/sweep-<time>/``). Exit 0 when every run is ok, 1 when any failed, 2 when a config is
bad (checked before anything runs).
"""

from __future__ import annotations

from controller.config import SIM_BACKENDS

EXAMPLES = """examples:
  fleet sweep fleet.toml lab/secure.toml                  a dry run of each, then a table
  fleet sweep fleet.toml --backend ideal --max-time 60 --json --out-dir runs/sweep
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("configs", nargs="+", metavar="CONFIG", help="fleet configs to run")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--out-dir", default=None, help="folder for the logs")
    parser.add_argument("--max-time", type=float, default=None, help="sim seconds per run")
    parser.add_argument("--backend", choices=SIM_BACKENDS, help="override sim.backend for all")


def run(args) -> int:
    import time
    from pathlib import Path

    from controller.cli import emit_json
    from controller.runtime.sweep import load_all, run_sweep, table

    first = load_all(args.configs)[0]  # ConfigError: exit 2 before anything runs
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out_dir = Path(args.out_dir) if args.out_dir else Path(first.log.dir) / f"sweep-{stamp}"
    rows = run_sweep(args.configs, out_dir, args.max_time, args.backend)
    failed = sum(r["status"] != "ok" for r in rows)
    if args.json:
        emit_json({"runs": rows, "ok": len(rows) - failed, "failed": failed, "logs": str(out_dir)})
    else:
        print(table(rows))
    return 1 if failed else 0
