"""Play a log back on the bus: the original keys and payloads, spaced as they were logged."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

from controller.config import load_config
from controller.io.bus import Bus
from controller.replay.log import read_log


def republish(
    path: str | Path,
    bus: Any,
    speed: float = 1.0,
    topics: list[str] | None = None,
    wait_matching: float = 0.0,
) -> int:
    """Publish a log's messages again on ``bus`` (raw payloads, original keys), spaced as they
    were logged divided by ``speed`` (0: as fast as possible). With ``wait_matching`` > 0, first
    wait up to that many seconds until every key has a subscriber. Returns the count published."""
    keys = topics if topics is not None else sorted({r.topic for r in read_log(path)})
    pubs = {k: bus.session.declare_publisher(k) for k in keys}
    try:
        deadline = time.monotonic() + wait_matching
        while wait_matching > 0 and time.monotonic() < deadline:
            if all(p.matching_status.matching for p in pubs.values()):
                break
            time.sleep(0.01)
        sent = 0
        t0_log: int | None = None
        t0 = time.monotonic()
        for rec in read_log(path, keys):
            if t0_log is None:
                t0_log = rec.log_time_ns
            if speed > 0:
                delay = t0 + (rec.log_time_ns - t0_log) / 1e9 / speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            pubs[rec.topic].put(rec.data)
            sent += 1
        return sent
    finally:
        for p in pubs.values():
            p.undeclare()


NOT_REPLAYED = ("/cmd", "/estop", "/sim/clock", "/sim/done")


def republish_run(
    log_path: str | Path,
    run_log: Any,
    config_path: str | None,
    speed: float,
    with_commands: bool,
    default_config: str,
) -> int:
    """``fleet replay --republish``: the log's keys on the recorded config's bus (or
    ``config_path``'s), without commands and e-stops unless ``with_commands``."""
    cfg = load_config(config_path) if config_path else run_log.config
    if cfg is None:
        cfg = load_config(default_config)
    keys = sorted(k for k in run_log.topics if with_commands or not k.endswith(NOT_REPLAYED))
    print(f"fleet replay: republishing {len(keys)} keys on {cfg.zenoh.listen}", file=sys.stderr)
    with Bus(cfg.zenoh, cfg.fleet.name) as bus:
        return republish(log_path, bus, speed, keys)
