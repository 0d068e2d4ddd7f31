"""The controller node's stage timings: each tick's sample, plan, safety and publish durations
from an injected clock, summarised for the run summary and ``fleet status``.

Part of ``ControllerNode`` (``controller/runtime/node.py``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

STAGES = ("sample", "plan", "safety", "publish")  # timed: sample+estimate, plan, safety, publish
TIMINGS = 200_000  # ticks of stage timings kept (the run summary's; about 3 h at 20 Hz)


class StageTimes:
    """The last ``TIMINGS`` ticks' stage durations (s), and the last 1 000 whole ticks'."""

    def __init__(self) -> None:
        self.stages: dict[str, deque[float]] = {k: deque(maxlen=TIMINGS) for k in STAGES}
        self.totals: deque[float] = deque(maxlen=1000)
        self.last_s: float | None = None  # the last tick's duration

    def record(self, marks: list[float]) -> None:
        """One tick's clock readings: before the first stage and after each."""
        for name, a, b in zip(STAGES, marks[:-1], marks[1:], strict=True):
            self.stages[name].append(b - a)
        self.last_s = marks[-1] - marks[0]
        self.totals.append(self.last_s)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per stage (and the mission's plan + safety as ``step_ms``): median, p90, max in ms."""
        if not self.stages["plan"]:
            return {}
        series = {f"{k}_ms": np.asarray(v) * 1e3 for k, v in self.stages.items()}
        series["filter_ms"] = series.pop("safety_ms")
        series["step_ms"] = series["plan_ms"] + series["filter_ms"]
        return {
            k: {
                "median": float(np.median(a)),
                "p90": float(np.percentile(a, 90)),
                "max": float(a.max()),
                "calls": len(a),
            }
            for k, a in series.items()
        }

    def percentiles(self) -> dict[str, float]:
        """The whole tick's p50/p99/max over the last 1 000 ticks, ms."""
        if not self.totals:
            return {}
        total = np.asarray(self.totals)
        return {
            "p50": float(np.median(total) * 1e3),
            "p99": float(np.percentile(total, 99) * 1e3),
            "max": float(total.max() * 1e3),
        }
