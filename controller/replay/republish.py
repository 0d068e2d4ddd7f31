"""Play a log back on the bus: the original keys and payloads, paced on the log's own time.

The pace is the run's clock, not the speed at which the original process happened to write:
log time in a dry run logged with sim-time stamps and in the lab (receive times), the messages'
own stamps (publish time) in dry-run logs from before sim-time stamps (whose log time was the
writer's wall clock, 0.8-16x off the run's). With a wait, nothing is published until every key
has a subscriber (a recorder started at the same moment misses nothing).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from controller.config import load_config
from controller.io.bus import Bus
from controller.replay.log import read_log


def pacing(stamps_ns: Iterable[int], speed: float) -> list[float]:
    """When (s after the first) each message is due at ``speed`` × the log's time: stamps
    that go back (a measurement stamped before the tick that carried it) are due at once."""
    out: list[float] = []
    first: int | None = None
    latest = 0
    for ns in stamps_ns:
        if first is None:
            first = latest = ns
        latest = max(latest, ns)
        out.append((latest - first) / 1e9 / speed if speed > 0 else 0.0)
    return out


def wait_for_subscribers(pubs: dict[str, Any], timeout: float) -> bool:
    """Wait up to ``timeout`` s until every publisher has a matching subscriber."""
    deadline = time.monotonic() + timeout
    while True:
        if all(p.matching_status.matching for p in pubs.values()):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)  # polling the subscribers' declarations (a handshake)


def republish(
    path: str | Path,
    bus: Any,
    speed: float = 1.0,
    topics: list[str] | None = None,
    wait_matching: float = 0.0,
    by_publish_time: bool = False,
    stats: dict[str, Any] | None = None,
) -> int:
    """Publish a log's messages again on ``bus`` (raw payloads, original keys), paced at
    ``speed`` × the log's time (0: as fast as possible; ``by_publish_time``: on the messages'
    own stamps instead of log time). With ``wait_matching`` > 0, first wait up to that many
    seconds until every key has a subscriber. Returns the count published; ``stats`` (if given)
    gets ``matched`` (every key had a subscriber), ``log_span_s`` and ``played_s``."""
    keys = topics if topics is not None else sorted({r.topic for r in read_log(path)})
    pubs = {k: bus.session.declare_publisher(k) for k in keys}
    try:
        matched = wait_for_subscribers(pubs, wait_matching) if wait_matching > 0 else None
        records = list(read_log(path, keys))
        stamps = [r.publish_time_ns if by_publish_time else r.log_time_ns for r in records]
        due = pacing(stamps, speed)
        t0 = time.monotonic()
        for rec, at in zip(records, due, strict=True):
            delay = t0 + at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            pubs[rec.topic].put(rec.data)
        if stats is not None:
            span = (max(stamps) - min(stamps)) / 1e9 if stamps else 0.0
            stats.update(matched=matched, log_span_s=span, played_s=round(time.monotonic() - t0, 3))
        return len(records)
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
    wait: float = 0.0,
    stats: dict[str, Any] | None = None,
) -> int:
    """``fleet replay --republish``: the log's keys on the recorded config's bus (or
    ``config_path``'s), without commands and e-stops unless ``with_commands``, paced on the
    log's own time (see the module doc), after waiting up to ``wait`` s for subscribers."""
    cfg = load_config(config_path) if config_path else run_log.config
    if cfg is None:
        cfg = load_config(default_config)
    keys = sorted(k for k in run_log.topics if with_commands or not k.endswith(NOT_REPLAYED))
    legacy_dry_run = run_log.mode.startswith("run/") and run_log.time_base != "sim"
    print(f"fleet replay: republishing {len(keys)} keys on {cfg.zenoh.listen}", file=sys.stderr)
    with Bus(cfg.zenoh, cfg.fleet.name) as bus:
        n = republish(log_path, bus, speed, keys, wait, legacy_dry_run, stats)
    if stats is not None and stats.get("matched") is False:
        print(f"fleet replay: not every key had a subscriber after {wait} s", file=sys.stderr)
    return n
