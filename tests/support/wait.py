"""Waiting on a condition with a deadline (a handshake, never a sleep standing in for one)."""

from __future__ import annotations

import threading


def wait_for(cond, timeout: float, what: str) -> None:
    """Poll a condition (a handshake), failing after ``timeout`` seconds spent waiting between
    looks: a condition that itself takes time (a ``fleet status`` query, ~1 s) stretches the
    wall time by its own, so a slow query never fails a handshake that was coming."""
    ev = threading.Event()
    waited = 0.0
    while not cond():
        if waited >= timeout:
            raise AssertionError(f"timed out waiting for {what}")
        ev.wait(0.02)
        waited += 0.02
