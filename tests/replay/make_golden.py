"""Regenerate the golden logs of the regression replay (``tests/replay/data/<name>.mcap``).

    python -m tests.replay.make_golden capture [transport] [--force]

Each golden log is the dry run of ``tests/replay/data/<name>.toml`` (ideal backend, seeded) on
a free loopback port, with the mission of ``MISSIONS`` (``capture``: the whole job;
``transport``: robots already holding the object carry it to its goal), with its run summary
beside it (``<name>.json``: what ``tests/replay/test_golden.py`` compares the replay's metrics
and verdict with). A log is only written when its run succeeded (``--force``: anyway), when the
regression replay of it agrees with itself, and when it is under 2 MB.

When to run it: after a deliberate change of the controller's behaviour (the regression replay
then fails on the old logs, naming the first tick and robot that changed). Commit the new logs
with the change, and say in the commit what changed in the commands and why.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from controller.config import load_config
from controller.replay.check import check_log
from controller.runtime.dry_run import DryRun
from controller.runtime.sweep import on_free_port

DATA = Path(__file__).resolve().parent / "data"
MAX_BYTES = 2 * 1024 * 1024
NAMES = ("capture", "transport")
# the mission each golden log runs (the transport log: robots already holding the object)
MISSIONS = {"capture": "capture", "transport": "transport"}


def make(name: str, force: bool = False) -> dict:
    cfg = on_free_port(load_config(DATA / f"{name}.toml"))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"{name}.mcap"
        summary = DryRun.of(cfg, MISSIONS[name], out).run()
        if summary["status"] != "ok" and not force:
            raise SystemExit(f"{name}: the run failed ({summary['failure']}); not written")
        size = out.stat().st_size
        if size > MAX_BYTES:
            raise SystemExit(f"{name}: {size} bytes > {MAX_BYTES}; not written")
        check = check_log(out, mission=MISSIONS[name])
        if not check["ok"]:
            raise SystemExit(f"{name}: the replay of the new log disagrees: {check['message']}")
        shutil.copyfile(out, DATA / f"{name}.mcap")
    keep = {k: v for k, v in summary.items() if k not in ("log", "wall_time_s", "mission")}
    (DATA / f"{name}.json").write_text(json.dumps(keep, indent=1, sort_keys=True) + "\n")
    return {"name": name, "status": summary["status"], "bytes": size, "check": check["message"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1].strip())
    ap.add_argument("names", nargs="+", choices=NAMES)
    ap.add_argument("--force", action="store_true", help="write a failed run's log too")
    args = ap.parse_args(argv)
    for name in args.names:
        print(json.dumps(make(name, args.force)), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
