"""The garbage collector and the real-time loop.

A full (generation 2) collection walks every live container object of the process. In the lab
daemon those are mostly what start-up made (zenoh, numpy, scipy, osqp, the mcap writer, the
config): measured on the README's lab, two collections of 80 and 99 ms in a 4-minute job on
this 2-core machine, and on the CI machine a 277 ms tick that let a robot's watchdog fire. So,
as real-time Python loops do (Instagram's ``gc.freeze``; openpilot's control processes):

- once the loop's state is built, ``gc.freeze()`` moves every object alive then to a permanent
  generation that no collection walks again; collections then walk only what the job made;
- a collection that still holds the loop longer than ``WARN_S`` is logged, with its generation.
"""

from __future__ import annotations

import gc
import logging
import time

log = logging.getLogger(__name__)

WARN_S = 0.02  # s: a collection longer than this is logged


class _Watch:
    def __init__(self) -> None:
        self.t0 = 0.0
        self.slow = 0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self.t0 = time.perf_counter()
            return
        took = time.perf_counter() - self.t0
        if took > WARN_S:
            self.slow += 1
            log.warning(
                "garbage collection held the loop %.0f ms (generation %d, %d slow so far)",
                took * 1e3,
                info.get("generation", -1),
                self.slow,
            )


def freeze_for_real_time() -> _Watch:
    """Collect once, freeze what is alive (start-up's objects are never walked again) and log
    slow collections from now on. Returns the watch (``slow``: collections over ``WARN_S``)."""
    gc.collect()
    gc.freeze()
    watch = _Watch()
    gc.callbacks.append(watch)
    return watch


def release(watch: _Watch) -> None:
    """Undo ``freeze_for_real_time`` (the loop is over)."""
    if watch in gc.callbacks:
        gc.callbacks.remove(watch)
    gc.unfreeze()
