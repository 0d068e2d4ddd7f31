"""Run one bench script and commit its figures as a row: ``bench/rows/<name>.json``.

    python bench/record.py approach [-- --ticks 200]
    python bench/record.py capture --as capture_fresh -- --suite-only --suite-seed 31337

A bench run with other arguments is a row of its own (``--as``: its name in ``bench/rows/``).

The row is the script's JSON (``result``) with where it came from: the command, the commit
(and whether the tree had changes), the date, the machine (cores, Python, platform, and the
seconds 10^7 pure-Python additions took just before: this shared machine's speed varies from
day to day) and the load average before and after the run. ``bench/pages.py`` turns the rows
into the results pages of the docs (``docs/results/``), so every figure there names its row; a
test checks the pages are current with the rows. Progress goes to stderr; the row's path is
printed last. A bench that exits non-zero with its JSON printed (a run that failed, a goal
missed) still gets its row, with ``exit`` saying so, and this exits 1.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ROWS = ROOT / "bench" / "rows"
# the code a row's figures come from: the tree but the docs and the rows themselves
CODE = (".", ":!docs", ":!bench/rows", ":!README.md", ":!CHANGELOG.md")


def _git(*args: str) -> str:
    try:
        out = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return ""
    return out.stdout.strip()


def machine() -> dict:
    return {
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(terse=True),
    }


def calibration() -> float:
    """Seconds for 10^7 pure-Python additions (best of 3): the machine's speed at the time, so
    rows from different machines (or one shared machine on different days) can be compared."""
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        acc = 0
        for i in range(10_000_000):
            acc += i
        best = min(best, time.perf_counter() - t0)
    return round(best, 3)


def load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def record(name: str, args: list[str], row_name: str | None = None) -> Path:
    script = ROOT / "bench" / f"{name}.py"
    if not script.is_file():
        raise SystemExit(f"record: no bench/{name}.py (the benches: ls bench/*.py)")
    before = load()
    speed = calibration()
    cmd = [sys.executable, str(script), *args]
    print(f"record: {' '.join(['python', f'bench/{name}.py', *args])}", file=sys.stderr)
    proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        result = json.loads(proc.stdout)
    except json.JSONDecodeError as exc:
        raise SystemExit(
            f"record: bench/{name}.py exited {proc.returncode} and printed no JSON object ({exc}):"
            " no row written"
        ) from exc
    row = {
        "bench": name,
        "row": row_name or name,
        "command": " ".join(["python", f"bench/{name}.py", *args]),
        "commit": _git("rev-parse", "--short=10", "HEAD"),
        "dirty": bool(_git("status", "--porcelain", "--untracked-files=no", "--", *CODE)),
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": {**machine(), "loop_1e7_s": speed},
        "load_before": before,
        "load_after": load(),
        # a bench that exits non-zero says its figures include a failure (a run that did not
        # deliver, a goal missed): the row keeps them and says so
        "exit": proc.returncode,
        "result": result,
    }
    ROWS.mkdir(parents=True, exist_ok=True)
    path = ROWS / f"{row_name or name}.json"
    path.write_text(json.dumps(row, indent=1) + "\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name", help="the bench script's name (bench/<name>.py)")
    ap.add_argument("--as", dest="row", help="the row's name (default: the bench's)")
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    ns = ap.parse_args(argv[:cut])  # the bench's own arguments come after --
    path = record(ns.name, argv[cut + 1 :], ns.row)
    print(path)
    code = json.loads(path.read_text())["exit"]
    if code:
        print(f"record: the bench exited {code} (a failure among its figures): the row says so")
        sys.exit(1)


if __name__ == "__main__":
    main()
