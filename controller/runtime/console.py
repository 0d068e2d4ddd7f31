"""The operator's console of ``fleet up``: a live panel on a terminal (``rich``), plain lines
otherwise, and the keys r (resume), e (e-stop), q (stop the lab).

The panel: per robot its agent's process, presence and link (the daemon's view), its e-stop
latch, the command rate it gets, its last warning; the job's phase, the object's way to its
goal and an ETA; the e-stop and what the operator must do next. Off a terminal, a line for each
change (a part ready, exited or restarted; the stage, phase or e-stop) and a progress line every
:data:`PROGRESS_EVERY` s.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable

from controller.runtime.lab import Part, Snapshot

PROGRESS_EVERY = 10.0  # s between the plain console's progress lines


def part_state(p: Part, now: float) -> str:
    """ "ready", "starting", "restarting in 3 s", "exited (code 1)" or "stopped"."""
    if not p.argv:  # an agent on the robot's own computer
        return "remote, ready" if p.ready else "remote, waiting"
    if p.restart_at is not None:
        return f"restarting in {max(0.0, p.restart_at - now):.0f} s"
    if p.proc is None:
        return "not started"
    if p.exit_code is not None:
        return f"exited (code {p.exit_code})"
    return "ready" if p.ready else "starting"


def next_step(snap: Snapshot, config: str) -> str:
    """What the operator must do now, in one line."""
    if snap.stage == "starting":
        return f"starting: waiting for {snap.waiting_for or 'the bus'} ({snap.t:.0f} s)"
    if snap.stage == "waiting" or (snap.stage == "running" and snap.estop == "engaged"):
        return (
            "stopped, waiting for an operator's resume: press r or run "
            f"`fleet resume --config {config}`"
        )
    if snap.stage == "running":
        return f"running: press e or run `fleet estop --config {config}` to stop every robot"
    return "stopping: the e-stop first, then every process"


def estop_word(state: str) -> str:
    """The hub's latch for a person: unknown means stopped (a fresh lab, fail closed)."""
    return {"unknown": "not yet released (stopped)"}.get(state, state)


def headline(snap: Snapshot) -> str:
    """One line: stage, phase, e-stop, the object's way to the goal, the job's time."""
    phase = snap.status.phase if snap.status is not None else "-"
    bits = [f"lab {snap.stage}", f"phase {phase}", f"e-stop {estop_word(snap.estop)}"]
    if snap.goal_distance is not None:
        eta = f", ETA {snap.eta_s:.0f} s" if snap.eta_s is not None else ""
        bits.append(f"object {snap.goal_distance:.2f} m from its goal{eta}")
    if snap.job_t is not None:
        bits.append(f"job {snap.job_t:.0f} s")
    return " | ".join(bits)


def robot_rows(snap: Snapshot, now: float) -> list[list[str]]:
    """The table's rows: one per part (robots with their presence, link, latch, command rate)."""
    present = {}
    if snap.status is not None:
        present = {r["id"]: r for r in snap.status.robots}
    rows = []
    for p in snap.parts:
        for name in p.robots or (p.name,):
            rows.append(_row(snap, p, name, present.get(name), now))
    return rows


def _row(snap: Snapshot, p: Part, name: str, r: dict | None, now: float) -> list[str]:
    seen = "-" if r is None else ("present" if r.get("present") else "absent")
    link = "-" if r is None else ("LOST" if r.get("link_lost") else "ok")
    if r is not None and r.get("skewed"):
        link = "SKEWED"  # its clock is off: its poses are dropped
    latch = snap.latches.get(f"robot/{name}", "-")
    if p.role in ("hub", "daemon"):  # one hub, one controller: their ids are their own
        holder = "hub/" if p.role == "hub" else "controller/"
        latch = next((v for k, v in snap.latches.items() if k.startswith(holder)), "-")
    hz = f"{snap.cmd_hz[name]:.0f}" if name in snap.cmd_hz else "-"
    restarts = str(p.restarts) if p.restarts else ""
    return [name, part_state(p, now), seen, link, latch, hz, restarts, p.last_warning]


COLUMNS = ["part", "process", "seen", "link", "e-stop", "cmd/s", "restarts", "last warning"]


class PlainConsole:
    """Line by line, for logs and pipes: only what changed, and progress now and then."""

    def __init__(self, config: str, out=None) -> None:
        self.config = config
        self.out = out or sys.stdout
        self._last: dict[str, str] = {}
        self._next_progress = PROGRESS_EVERY

    def _say(self, snap: Snapshot, text: str) -> None:
        print(f"[{snap.t:6.1f} s] {text}", file=self.out, flush=True)

    def __call__(self, snap: Snapshot) -> None:
        now_states = {}
        now = time.monotonic()
        for p in snap.parts:
            if p.proc is not None or (not p.argv and p.started):
                now_states[f"part {p.name}"] = part_state(p, now)
        now_states["stage"] = snap.stage
        now_states["phase"] = snap.status.phase if snap.status is not None else ""
        now_states["e-stop"] = estop_word(snap.estop)
        now_states["next"] = next_step(snap, self.config) if snap.stage != "starting" else ""
        for key, value in now_states.items():
            if value and self._last.get(key) != value:
                self._say(snap, value if key == "next" else f"{key}: {value}")
        self._last = now_states
        if snap.t >= self._next_progress and snap.stage in ("waiting", "running"):
            self._say(snap, headline(snap))
            self._next_progress = snap.t + PROGRESS_EVERY

    def close(self) -> None:
        pass


class LiveConsole:
    """A live panel (rich) redrawn every snapshot."""

    def __init__(self, config: str) -> None:
        from rich.console import Console
        from rich.live import Live

        self.config = config
        self.console = Console(stderr=False)
        self.live = Live(console=self.console, auto_refresh=False, transient=False)
        self.live.start()

    def __call__(self, snap: Snapshot) -> None:
        from rich.console import Group
        from rich.table import Table
        from rich.text import Text

        table = Table(title=headline(snap), title_justify="left", expand=True)
        for c in COLUMNS:
            table.add_column(c, overflow="fold" if c == "last warning" else "ellipsis")
        for row in robot_rows(snap, time.monotonic()):
            table.add_row(*row)
        step = Text(next_step(snap, self.config), style="bold")
        keys = Text("keys: r resume · e e-stop · q stop the lab (Ctrl-C: the same)", style="dim")
        self.live.update(Group(table, step, keys), refresh=True)

    def close(self) -> None:
        self.live.stop()


class Keys:
    """Single keys from the terminal (cbreak mode, restored on close): r, e, q."""

    def __init__(self, on_key: Callable[[str], None]) -> None:
        import termios
        import tty

        self.fd = sys.stdin.fileno()
        self.saved = termios.tcgetattr(self.fd)
        tty.setcbreak(self.fd)
        self.on_key = on_key
        self.closed = threading.Event()
        threading.Thread(target=self._run, name="console-keys", daemon=True).start()

    def _run(self) -> None:
        import select

        while not self.closed.is_set():
            ready, _, _ = select.select([self.fd], [], [], 0.2)
            if ready:
                ch = os.read(self.fd, 1).decode(errors="replace").lower()
                self.on_key(ch)

    def close(self) -> None:
        import termios

        self.closed.set()
        with contextlib.suppress(Exception):
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self.saved)


def make_console(config: str, live: bool):
    """The live panel on a terminal (``live``), plain lines otherwise."""
    return LiveConsole(config) if live else PlainConsole(config)


class RunProgress:
    """``fleet run``'s progress bar on a terminal (stderr): sim time against ``sim.max_time``,
    the phase, the object's distance to its goal, the wall time and an ETA from the pace of
    the last stretch towards the goal."""

    def __init__(self, max_time: float) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(
            TextColumn("[bold]{task.fields[phase]:<9}"),
            BarColumn(),
            TextColumn("sim {task.completed:6.1f} s of {task.total:.0f}"),
            TextColumn("{task.fields[goal]}"),
            TimeElapsedColumn(),
            console=Console(stderr=True),
            transient=True,
        )
        self.task = self.progress.add_task("run", total=max_time, phase="plan", goal="")
        self.progress.start()
        # the log above the bar, not through it (rich's stderr proxy); the INFO progress of
        # the stages is the bar's now: warnings only, unless -v asked for debug
        self._handlers = []
        root = logging.getLogger()
        for h in root.handlers:
            if isinstance(h, logging.StreamHandler):
                self._handlers.append((h, h.stream, h.level))
                h.setStream(sys.stderr)
                if root.level > logging.DEBUG:
                    h.setLevel(logging.WARNING)
        self._pace: list[tuple[float, float]] = []  # (sim t, m to goal)
        self._last = -1.0

    def update(self, t: float, phase: str, figures: dict) -> None:
        if t - self._last < 0.25:  # a redraw every quarter second of sim time is plenty
            return
        self._last = t
        goal = ""
        d = figures.get("to_goal_m")
        if isinstance(d, float):
            self._pace = [(a, b) for a, b in self._pace if a > t - 20.0] + [(t, d)]
            t0, d0 = self._pace[0]
            pace = (d0 - d) / (t - t0) if t - t0 > 3.0 else 0.0
            eta = f", ETA {d / pace:.0f} s of sim" if pace > 0.005 else ""
            goal = f"object {d:.2f} m from its goal{eta}"
        self.progress.update(self.task, completed=t, phase=phase, goal=goal)

    def close(self) -> None:
        self.progress.stop()
        for h, stream, level in self._handlers:
            h.setStream(stream)
            h.setLevel(level)
