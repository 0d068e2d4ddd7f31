"""``fleet sweep``: the dry runs of several configs, one after the other, each on a free
loopback port (so they never meet each other or a running daemon), one summary line each and a
table at the end."""

from __future__ import annotations

import dataclasses
import logging
import socket
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from controller.config import FleetConfig, load_config
from controller.outcome import verdict_line

log = logging.getLogger(__name__)

COLUMNS = (
    ("config", 28),
    ("status", 7),
    ("phase", 10),
    ("reason", 16),
    ("sim_s", 7),
    ("wall_s", 7),
    ("arrest_s", 8),
    ("clearance_m", 11),
)


def free_port() -> int:
    """A TCP port on 127.0.0.1 free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def on_free_port(cfg: FleetConfig) -> FleetConfig:
    """The config with its bus on a free loopback port (and nothing to connect to), in the
    protocol of its first listen endpoint (a TLS-only config stays TLS)."""
    first = cfg.zenoh.listen[0] if cfg.zenoh.listen else "tcp/"
    proto = first.split("/", 1)[0] if first.split("/", 1)[0] in ("tcp", "tls") else "tcp"
    zenoh = dataclasses.replace(
        cfg.zenoh, listen=(f"{proto}/127.0.0.1:{free_port()}",), connect=(), mode="peer"
    )
    return dataclasses.replace(cfg, zenoh=zenoh)


def load_all(paths: list[str]) -> list[FleetConfig]:
    """Every config, loaded before anything runs (a bad one: ConfigError, exit 2)."""
    return [load_config(p) for p in paths]


def run_one(cfg: FleetConfig, out: Path, max_time: float | None) -> dict[str, Any]:
    """One dry run as a sweep row (a run that cannot start is a row with status ``error``)."""
    from controller.mission.job import MissionError
    from controller.runtime.dry_run import DryRun

    row: dict[str, Any] = {"config": cfg.source, "log": str(out), "backend": cfg.sim.backend}
    t0 = time.monotonic()
    try:
        summary = DryRun.of(on_free_port(cfg), "capture", out, max_time=max_time).run()
    except MissionError as exc:
        return {**row, "status": "error", "phase": None, "reason": "mission", "detail": str(exc)}
    except Exception as exc:  # noqa: BLE001 - one broken run must not end the sweep
        log.exception("%s: the dry run failed", cfg.source)
        return {
            **row,
            "status": "error",
            "phase": None,
            "reason": type(exc).__name__,
            "detail": str(exc),
            "wall_time_s": round(time.monotonic() - t0, 3),
        }
    failure = summary.get("failure") or {}
    return {
        **row,
        "status": summary["status"],
        "phase": summary.get("phase"),
        "reason": failure.get("reason"),
        "detail": failure.get("detail"),
        "sim_time_s": summary.get("sim_time_s"),
        "wall_time_s": summary.get("wall_time_s"),
        "arrest_time_s": summary.get("arrest_time_s"),
        "min_clearance_m": summary.get("min_clearance_m"),
        "verdict": summary.get("verdict"),
        "log": summary.get("log", str(out)),
        "verdict_line": verdict_line(summary),
    }


def line(i: int, n: int, row: dict[str, Any]) -> str:
    """The one-line summary of a finished run: its verdict line (``controller.outcome``), or
    for a run that could not start, the error."""
    if row.get("verdict_line"):
        head = f"[{i}/{n}] {row['config']}: {row['status']}"
        return f"{head}: {row['verdict_line']}; log {row['log']}"
    what = f"{row['status']}"
    if row.get("reason"):
        what += f" ({row['reason']}: {row.get('detail') or ''})".rstrip(": )") + ")"
    return (
        f"[{i}/{n}] {row['config']}: {what}, phase {row.get('phase')}, "
        f"sim {row.get('sim_time_s')} s in {row.get('wall_time_s')} s, log {row['log']}"
    )


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3f}"
    return "-" if v is None else str(v)


def table(rows: list[dict[str, Any]]) -> str:
    """The sweep's table (text)."""
    keys = {
        "sim_s": "sim_time_s",
        "wall_s": "wall_time_s",
        "arrest_s": "arrest_time_s",
        "clearance_m": "min_clearance_m",
    }
    head = "  ".join(f"{name:<{w}}" for name, w in COLUMNS)
    out = [head, "-" * len(head)]
    for r in rows:
        cells = []
        for name, w in COLUMNS:
            v = _cell(r.get(keys.get(name, name)))
            if name == "config" and len(v) > w:
                v = "…" + v[-(w - 1) :]
            cells.append(f"{v:<{w}}")
        out.append("  ".join(cells).rstrip())
    ok = sum(r["status"] == "ok" for r in rows)
    out.append(f"{ok} of {len(rows)} runs ok")
    return "\n".join(out)


def run_sweep(
    paths: list[str],
    out_dir: Path,
    max_time: float | None = None,
    backend: str | None = None,
    progress: TextIO | None = None,
) -> list[dict[str, Any]]:
    """Every config's dry run, in order; a row per run (see ``run_one``); progress lines to
    ``progress`` (None: the stderr of the moment, not the one at import)."""
    progress = sys.stderr if progress is None else progress
    cfgs = load_all(paths)
    if backend:
        cfgs = [
            dataclasses.replace(c, sim=dataclasses.replace(c.sim, backend=backend)) for c in cfgs
        ]
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, (cfg, path) in enumerate(zip(cfgs, paths, strict=True), 1):
        out = out_dir / f"{i:02d}-{Path(path).stem}.mcap"
        print(f"[{i}/{len(cfgs)}] {cfg.source}: running ({cfg.sim.backend})", file=progress)
        row = run_one(cfg, out, max_time)
        rows.append(row)
        print(line(i, len(cfgs), row), file=progress)
    return rows
