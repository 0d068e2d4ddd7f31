"""The daemon's loop and the garbage collector: what is alive when the loop starts is frozen
(no collection walks it again), a slow collection is logged with its generation, and the loop's
end unfreezes."""

from __future__ import annotations

import gc
import logging

from controller.runtime import gcpause


def test_startup_objects_are_frozen_and_a_slow_collection_is_logged(caplog, monkeypatch):
    startup = [[i] for i in range(50_000)]  # containers alive when the loop starts
    watch = gcpause.freeze_for_real_time()
    try:
        assert gc.get_freeze_count() >= len(startup)  # out of every collection's walk
        clock = iter([10.0, 10.05, 11.0, 11.001])
        monkeypatch.setattr(gcpause.time, "perf_counter", lambda: next(clock))
        with caplog.at_level(logging.WARNING, logger="controller.runtime.gcpause"):
            watch("start", {"generation": 2})
            watch("stop", {"generation": 2, "collected": 0, "uncollectable": 0})
            watch("start", {"generation": 0})
            watch("stop", {"generation": 0, "collected": 0, "uncollectable": 0})
        assert watch.slow == 1
        assert "held the loop 50 ms (generation 2" in caplog.text
    finally:
        gcpause.release(watch)
    assert gc.get_freeze_count() == 0 and watch not in gc.callbacks
