"""Typed plan events against the ``(kind, dict)`` tuples they replaced: prints ONE JSON object.

Every plan event of both golden logs (tests/replay/data), as logged. Per event, in the same
process, the median over ``--repeats`` passes of:

- ``publish``: what the node does per event: ``to_dict()`` then ``wire.encode`` of the PlanEvent
  (baseline: the dict as it was, encoded the same way);
- ``read``: what replay, the scene and the figures do per logged event: ``parse_event`` (checks
  the fields, builds the dataclass) and one field read (baseline: ``dict(data)`` and
  ``data.get``).

Ratios are typed / baseline. The per-tick cost is what matters: a tick publishes 0 to 3 events
(one local plan every interval is the most). Usage: ``python bench/events.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller import wire  # noqa: E402
from controller.events import parse_event  # noqa: E402
from controller.io.recorder import read_log  # noqa: E402

DATA = Path(__file__).resolve().parent.parent / "tests" / "replay" / "data"


def logged_events() -> list[wire.PlanEvent]:
    out = []
    for name in ("capture", "transport"):
        for rec in read_log(DATA / f"{name}.mcap"):
            parsed = wire.parse_key(rec.topic)
            if parsed is not None and parsed.topic.name == "plan":
                out.append(wire.decode(wire.PlanEvent, rec.data))
    return out


def per_event_us(fn, items, repeats: int) -> float:
    """Median over ``repeats`` passes of the mean time per item (µs)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for x in items:
            fn(x)
        times.append((time.perf_counter() - t0) / len(items) * 1e6)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args(argv)
    msgs = logged_events()
    typed = [(m, parse_event(m.kind, m.data)) for m in msgs]
    raw = [(m, (m.kind, m.data)) for m in msgs]

    def publish_typed(item):
        m, ev = item
        return wire.encode(wire.PlanEvent(t=m.t, seq=m.seq, kind=ev.kind, data=ev.to_dict()))

    def publish_tuple(item):
        m, (kind, data) = item
        return wire.encode(wire.PlanEvent(t=m.t, seq=m.seq, kind=kind, data=data))

    def read_typed(m):
        ev = parse_event(m.kind, m.data)
        return getattr(ev, "t", None)

    def read_dict(m):
        data = dict(m.data)
        return data.get("t")

    out = {
        "events": len(msgs),
        "kinds": sorted({m.kind for m in msgs}),
        "repeats": args.repeats,
        "load_avg_1m": round(os.getloadavg()[0], 2),
    }
    for name, typed_fn, base_fn, items_t, items_b in (
        ("publish", publish_typed, publish_tuple, typed, raw),
        ("read", read_typed, read_dict, msgs, msgs),
    ):
        t_us = per_event_us(typed_fn, items_t, args.repeats)
        b_us = per_event_us(base_fn, items_b, args.repeats)
        out[name] = {
            "typed_us_median": round(t_us, 2),
            "baseline_us_median": round(b_us, 2),
            "ratio": round(t_us / b_us, 3),
        }
    out["load_avg_1m_after"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
