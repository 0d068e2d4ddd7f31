"""The long-lived commands' stop on SIGINT/SIGTERM (``fleet hub``, ``world``, ``daemon``,
``driver``, ``record``): the handler must not take the lock of the event the main thread waits
on. With ``signal.signal(sig, lambda *_: stop.set())`` a signal that lands while the main thread
is inside ``stop.wait()`` (holding the event's lock) deadlocks the process: a hub its daemon had
started never stopped on the SIGTERM of its daemon's death (seen in make test)."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from controller.commands import stop_on_signals


@pytest.fixture
def restore_handlers():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def test_the_handler_sets_the_stop_even_while_its_lock_is_held(restore_handlers):
    stop = stop_on_signals()
    handler = signal.getsignal(signal.SIGTERM)
    done = threading.Event()

    def interrupted_wait() -> None:
        # what the interpreter does when the signal lands inside stop.wait(): the handler
        # runs while the event's lock is held by the same thread
        with stop._cond:  # noqa: SLF001 - the lock Event.wait holds
            handler(signal.SIGTERM, None)
        done.set()

    t = threading.Thread(target=interrupted_wait, daemon=True)
    t.start()
    t.join(timeout=5.0)
    assert done.is_set(), "the signal handler deadlocked on the stop event's lock"
    assert stop.wait(5.0)


def test_a_real_sigterm_wakes_a_main_thread_blocked_in_wait(restore_handlers):
    stop = stop_on_signals()
    threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGTERM)).start()
    assert stop.wait(10.0)
    assert stop.is_set()
