"""Whether ``fleet run --gui`` can open the pybullet window here (checked before anything
starts: pybullet's GUI without a display kills the process, with no log and no JSON)."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping


def gui_problem(
    backend: str, environ: Mapping[str, str] | None = None, platform: str | None = None
) -> str | None:
    """Why the GUI cannot be shown (None: it can): the backend has no window, or on Linux no
    X display is set."""
    env = os.environ if environ is None else environ
    plat = sys.platform if platform is None else platform
    if backend != "pybullet":
        return (
            f"the {backend!r} backend has no window; the GUI shows the pybullet world "
            "(--backend pybullet)"
        )
    if plat.startswith("linux") and not env.get("DISPLAY"):
        return "no display (DISPLAY is not set): run without --gui, or under xvfb-run"
    return None
