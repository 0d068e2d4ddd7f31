"""A CPU hog on every core, beside a test that must hold up on a loaded machine."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys

HOG = "import time\nend = time.monotonic() + 600\nwhile time.monotonic() < end:\n    pass\n"


@contextlib.contextmanager
def cpu_hogs():
    """One busy process per core (at least two), killed on exit (they end by themselves after
    600 s if a test dies without its ``finally``)."""
    hogs = [
        subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(max(2, os.cpu_count() or 2))
    ]
    try:
        yield hogs
    finally:
        for h in hogs:
            h.kill()
            h.wait()
