"""``fleet up``: the whole lab from one config, each part its own process, supervised.

The parts, in order, each started once the one before is ready *as seen on the bus* (never a
fixed wait):

1. ``fleet hub``: the meeting point and keeper of the latched e-stop. Ready when the lab's own
   session (an operator's, as ``fleet status`` opens) connects to ``zenoh.listen``.
2. ``fleet world`` when rehearsing (a robot of the config is a body of the stand-in world: a
   ``sim`` robot, or a MAVLink/ROS 2 robot named by ``--mavlink``/``--ros2``). Ready when its
   liveliness token ``alive/world/main`` is seen. Real robots: no world.
3. one ``fleet driver`` per robot, all at once. Each ready when its ``alive/robot/<id>`` token is
   seen (the agent declares it once its robot answers).
4. ``fleet daemon --mission <M>``: the controller. Ready when ``alive/controller/*`` is seen.

Every part writes its own log file in the run's folder (``<log.dir>/<fleet>-lab-<time>/``,
with the daemon's MCAP). A crashed agent or hub is started again with back-off (1 s doubling to
30 s, as ``ros2 launch``'s respawn); a restart never lifts an e-stop (a fresh holder starts
stopped and adopts the hub's latch). The daemon's exit is the job's end; the world's exit ends
the rehearsal. On the job's end, or a stop (SIGINT/SIGTERM, the console's q), the lab engages
the e-stop first (every robot stopped), then stops the daemon (its MCAP closed whole), the
agents, the world and the hub, in that order.

The lab's state goes to ``<log.dir>/<fleet>-lab.json`` (written atomically) for ``fleet up
--detach`` and ``fleet down``: its pid, run folder, stage, and at the end the verdict and the
exit code.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controller import wire
from controller.config import FleetConfig

log = logging.getLogger(__name__)

BACKOFF_FIRST = 1.0  # s before the first restart of a crashed part
BACKOFF_MAX = 30.0  # s: the back-off doubles up to this
STABLE_AFTER = 30.0  # s up: a part that ran this long gets its back-off reset
POLL = 0.5  # s between the supervisor's looks at its processes and the bus (a status query each)
STOP_WAIT = 20.0  # s a part may take to stop on SIGTERM before it is killed
ESTOP_AT_STOP = 3.0  # s the e-stop at the lab's end may take to be confirmed


@dataclass
class Part:
    """One process of the lab."""

    name: str  # "hub", "world", "daemon", or the robots' ids ("r1", or "r1,r2" for a group)
    role: str  # "hub", "world", "agent", "daemon"
    argv: list[str]
    log_path: Path
    respawn: bool
    proc: subprocess.Popen | None = None
    ready: bool = False
    started: float = 0.0  # monotonic
    restarts: int = 0
    backoff: float = BACKOFF_FIRST
    restart_at: float | None = None  # monotonic: a crashed part's next start
    exit_code: int | None = None
    last_warning: str = ""

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    @property
    def robots(self) -> tuple[str, ...]:
        """The robots whose agents this part runs (none for hub, world and daemon)."""
        return tuple(self.name.split(",")) if self.role == "agent" else ()


def rehearsal_bodies(cfg: FleetConfig, mavlink: str | None, ros2: str | None) -> bool:
    """Whether the lab needs the stand-in world: a robot of the config is a body of it."""
    return any(r.spec.world_body for r in cfg.robots) or bool(mavlink) or bool(ros2)


def plan_parts(
    cfg: FleetConfig,
    config_path: str,
    run_dir: Path,
    mission: str,
    mavlink: str | None = None,
    ros2: str | None = None,
    connect_timeout: float = 180.0,
    remote: tuple[str, ...] = (),
    viz: bool = False,
    agents_per_process: int = 1,
) -> list[Part]:
    """The lab's processes in their start order (see the module doc). ``remote``: robots whose
    agents run elsewhere (on the robot's own computer): not started here, waited for all the
    same. ``viz``: the daemon serves the live view."""
    fleet = [sys.executable, "-m", "controller.cli"]
    c = ["--config", config_path]
    parts = [Part("hub", "hub", [*fleet, "hub", *c], run_dir / "hub.log", respawn=True)]
    if rehearsal_bodies(cfg, mavlink, ros2):
        extra = (["--mavlink", mavlink] if mavlink else []) + (["--ros2", ros2] if ros2 else [])
        parts.append(
            Part("world", "world", [*fleet, "world", *c, *extra], run_dir / "world.log", False)
        )
    for rid in remote:  # started on the robot's computer: the lab only waits for its token
        parts.append(Part(rid, "agent", [], run_dir / f"{rid}.log", respawn=False))
    here = [rid for rid in cfg.robot_ids if rid not in remote]
    per = max(1, agents_per_process)
    for group in (here[i : i + per] for i in range(0, len(here), per)):
        ids = ",".join(group)
        argv = [*fleet, "driver", ids, *c, "--connect-timeout", f"{connect_timeout:g}"]
        log_name = group[0] if len(group) == 1 else f"agents-{group[0]}-{group[-1]}"
        parts.append(Part(ids, "agent", argv, run_dir / f"{log_name}.log", respawn=True))
    daemon = [*fleet, "daemon", *c, "--mission", mission, "--out", str(run_dir / "daemon.mcap")]
    daemon += ["--viz"] if viz else []
    parts.append(Part("daemon", "daemon", daemon, run_dir / "daemon.log", respawn=False))
    return parts


def state_path(cfg: FleetConfig) -> Path:
    """Where a running lab of this fleet keeps its state (``fleet down`` reads it)."""
    return Path(cfg.log.dir) / f"{cfg.fleet.name}-lab.json"


def write_state(path: Path, state: dict[str, Any]) -> None:
    """The lab's state, atomically (a reader never sees half a file)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(state, indent=1))
    os.replace(tmp, path)


def read_state(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, ended but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state != "Z"


@dataclass
class Snapshot:
    """What the console shows: the lab's parts, the daemon's status, the e-stop, the object."""

    t: float  # s since the lab started
    stage: str  # "starting", "waiting" (for an operator's resume), "running", "stopping", "ended"
    waiting_for: str = ""  # the part bring-up waits for
    parts: list[Part] = field(default_factory=list)
    status: wire.FleetStatus | None = None
    estop: str = "unknown"  # "engaged", "released", "unknown" (the hub's latch)
    latches: dict[str, str] = field(default_factory=dict)  # every holder's, by role/id
    cmd_hz: dict[str, float] = field(default_factory=dict)
    goal_distance: float | None = None  # m, the object's estimate to object.goal
    eta_s: float | None = None
    job_t: float | None = None  # s since the operator's resume (the job's start)


class LabWatch:
    """The lab's own session on the bus (an operator's identity, as ``fleet status``): readiness
    of the parts, the daemon's status, the hub's latch, command rates and the object's way to
    its goal, for the console."""

    def __init__(self, cfg: FleetConfig, identity=None) -> None:
        self.cfg = cfg
        self.identity = identity
        self.bus = None
        self._lock = threading.Lock()
        self._cmds: dict[str, list[float]] = {}
        self._object: wire.ObjectState | None = None
        self._progress: list[tuple[float, float]] = []  # (monotonic, distance to goal)
        self._boxes: list = []  # the subscriptions' inboxes, drained (the callbacks count)

    def connect(self) -> bool:
        """Try once to join ``zenoh.listen`` (the hub); True when joined."""
        from controller.io.bus import Bus, BusError

        if self.bus is not None:
            return True
        try:
            self.bus = Bus(
                self.cfg.zenoh,
                self.cfg.fleet.name,
                mode="client",
                listen=[],
                connect=list(self.cfg.zenoh.listen),
                identity=self.identity,
            )
        except BusError:
            return False
        self._subscribe()
        return True

    def _subscribe(self) -> None:
        def on_cmd(item) -> None:
            parsed = wire.parse_key(item.key, self.cfg.fleet.name)
            if parsed is not None:
                with self._lock:
                    self._cmds.setdefault(parsed.id, []).append(time.monotonic())

        def on_object(item) -> None:
            with self._lock:
                self._object = item.msg

        try:
            for topic, cb in (("robot_cmd", on_cmd), ("object_state", on_object)):
                t = wire.TOPICS[topic]
                key = t.wildcard(self.cfg.fleet.name)
                box = self.bus.subscribe(key, t.msg, on_message=cb, lossless=True)
                self._boxes.append(box)  # unbounded, drained every look
        except Exception as exc:  # noqa: BLE001 - an ACL that forbids it: the panel shows less
            log.info("the console sees no commands or object state: %s", exc)

    def alive(self, role: str) -> list[str]:
        return [] if self.bus is None else self.bus.alive_ids(role, timeout=0.5)

    def status(self) -> wire.FleetStatus | None:
        if self.bus is None:
            return None
        from controller.runtime.claim import newest_status

        replies = self.bus.query("status", wire.FleetStatus, timeout=0.5)
        return newest_status(replies) if replies else None

    def latches(self) -> dict[str, str]:
        """Every latch holder's state, "engaged" or "released", by ``role/id``."""
        if self.bus is None:
            return {}
        out = {}
        for key, msg in self.bus.query_replies(self.bus.estop_wildcard(), wire.EStop, 0.5):
            parsed = wire.parse_key(key, self.bus.fleet)
            if parsed is not None:
                role = parsed.parts.get("role", "")
                out[f"{role}/{parsed.id}"] = "engaged" if msg.engaged else "released"
        return out

    def rates(self, window: float = 2.0) -> dict[str, float]:
        """Commands per second to each robot over the last ``window`` s."""
        for box in self._boxes:
            box.drain()
        now = time.monotonic()
        with self._lock:
            for times in self._cmds.values():
                while times and times[0] < now - window:
                    times.pop(0)
            return {rid: len(t) / window for rid, t in self._cmds.items()}

    def goal_progress(self) -> tuple[float | None, float | None]:
        """(m from the object's estimate to its goal, s to go at the recent pace)."""
        goal = self.cfg.object.goal
        with self._lock:
            obj = self._object
        if goal is None or obj is None:
            return None, None
        d = float(((obj.x - goal[0]) ** 2 + (obj.y - goal[1]) ** 2) ** 0.5)
        now = time.monotonic()
        self._progress.append((now, d))
        self._progress = [(t, v) for t, v in self._progress if t > now - 20.0]
        t0, d0 = self._progress[0]
        pace = (d0 - d) / (now - t0) if now - t0 > 3.0 else 0.0
        return d, (d / pace if pace > 0.005 else None)

    def put(self, word: str, reason: str = "", timeout: float = 5.0) -> dict[str, Any] | None:
        """``fleet estop`` / ``fleet resume`` from the console (None: not connected)."""
        if self.bus is None:
            return None
        import getpass
        import socket

        from controller.runtime.estop import put_estop

        source = f"{getpass.getuser()}@{socket.gethostname()} (fleet up)"
        return put_estop(self.bus, self.cfg, word, source, reason, timeout)

    def close(self) -> None:
        if self.bus is not None:
            self.bus.close()
            self.bus = None


def last_warning(path: Path, limit: int = 4096) -> str:
    """The last WARNING or ERROR line of a part's log ("" when none), its message only."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - limit))
            lines = f.read().decode(errors="replace").splitlines()
    except OSError:
        return ""
    for line in reversed(lines):
        for level in (" WARNING ", " ERROR "):
            if level in line:
                return line.split(level, 1)[1].split(": ", 1)[-1].strip()
    return ""


class Lab:
    """The supervisor: starts the parts in order, watches them, restarts the ones that may be,
    stops them all at the end. ``render(snapshot)`` is the console's; ``stop`` ends the lab."""

    def __init__(
        self,
        cfg: FleetConfig,
        parts: list[Part],
        run_dir: Path,
        stop: threading.Event,
        render: Callable[[Snapshot], None],
        ready_timeout: float = 180.0,
        identity=None,
        state_file: Path | None = None,
    ) -> None:
        self.cfg = cfg
        self.parts = parts
        self.run_dir = run_dir
        self.stop = stop
        self.render = render
        self.ready_timeout = ready_timeout
        self.watch = LabWatch(cfg, identity)
        self.state_file = state_file
        self.t0 = time.monotonic()
        self.stage = "starting"
        self.waiting_for = ""
        self.resumed_at: float | None = None
        self.ready_s: float | None = None
        self.failure: str | None = None  # why the lab ended on its own (not the job's reason)
        self.job_ended = False  # the daemon exited by itself: the job's end
        self.stopped_at: float | None = None  # monotonic: the lab began to stop
        self.final_estop: dict[str, Any] | None = None  # the e-stop at the end, as confirmed
        self.commands: list[str] = []  # console keys: "resume", "estop", handled in the loop
        self._cmd_lock = threading.Lock()
        self._snap: Snapshot | None = None

    # -- state, shown and saved
    def snapshot(self, with_bus: bool = True) -> Snapshot:
        snap = Snapshot(
            t=time.monotonic() - self.t0,
            stage=self.stage,
            waiting_for=self.waiting_for,
            parts=self.parts,
        )
        if with_bus and self.watch.bus is not None:
            snap.status = self.watch.status()
            snap.latches = self.watch.latches()
            hub = [v for k, v in snap.latches.items() if k.startswith("hub/")]
            snap.estop = hub[0] if hub else "unknown"
            snap.cmd_hz = self.watch.rates()
            snap.goal_distance, snap.eta_s = self.watch.goal_progress()
        if self.resumed_at is not None:
            snap.job_t = time.monotonic() - self.resumed_at
        for p in self.parts:
            p.last_warning = last_warning(p.log_path)
        self._snap = snap
        return snap

    def save(self, **more: Any) -> None:
        if self.state_file is None:
            return
        state = {
            "pid": os.getpid(),
            "fleet": self.cfg.fleet.name,
            "run_dir": str(self.run_dir),
            "log": str(self.run_dir / "daemon.mcap"),
            "stage": self.stage,
            "ready_s": None if self.ready_s is None else round(self.ready_s, 2),
            "parts": {
                p.name: {
                    "pid": p.proc.pid if p.proc else None,
                    "ready": p.ready,
                    "restarts": p.restarts,
                    "log": str(p.log_path),
                }
                for p in self.parts
            },
            **more,
        }
        write_state(self.state_file, state)

    def command(self, word: str) -> None:
        """A console key: "resume" or "estop" (done on the supervisor's thread)."""
        with self._cmd_lock:
            self.commands.append(word)

    # -- processes
    def start(self, part: Part) -> None:
        if not part.argv:  # a remote agent: started elsewhere
            part.started = time.monotonic()
            return
        log_file = open(part.log_path, "a")  # noqa: SIM115 - the child keeps it
        try:
            part.proc = subprocess.Popen(
                part.argv,
                stdout=log_file,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,  # a Ctrl-C in the terminal reaches the supervisor only
                env=dict(os.environ, PYTHONUNBUFFERED="1"),
            )
        finally:
            log_file.close()
        part.started = time.monotonic()
        part.ready = False
        part.restart_at = None
        part.exit_code = None

    def _reap(self, part: Part) -> bool:
        """Whether ``part`` has exited since the last look (its exit code kept)."""
        if part.proc is None or part.exit_code is not None:
            return False
        code = part.proc.poll()
        if code is None:
            return False
        part.exit_code = code
        part.ready = False
        return True

    def _respawn(self, part: Part, now: float) -> None:
        """A crashed part that may be restarted: schedule it with back-off; start it when due."""
        if part.exit_code is not None and part.restart_at is None:
            if now - part.started > STABLE_AFTER:
                part.backoff = BACKOFF_FIRST
            part.restart_at = now + part.backoff
            log.warning(
                "%s exited (code %s): restarting in %.0f s (see %s)",
                part.name,
                part.exit_code,
                part.backoff,
                part.log_path,
            )
            part.backoff = min(BACKOFF_MAX, part.backoff * 2)
        if part.restart_at is not None and now >= part.restart_at:
            part.restarts += 1
            self.start(part)

    def _ready(self, part: Part) -> bool:
        if part.role == "hub":
            return self.watch.connect()
        if part.role == "world":
            return "main" in self.watch.alive("world")
        if part.role == "agent":
            alive = set(self.watch.alive("robot"))
            return alive.issuperset(part.robots) and (part.proc is None or part.running())
        return bool(self.watch.alive("controller"))

    # -- the lab's life
    def run(self) -> int | None:
        """Bring up, supervise until the job ends or ``stop``; stop everything. Returns the
        daemon's exit code when the job ended (None: the lab ended before the job did: a stop,
        a part that failed)."""
        try:
            if self.bring_up():
                self.supervise()
        finally:
            self.shut_down()
        return self.parts[-1].exit_code if self.job_ended else None

    def _tick(self) -> None:
        self.render(self.snapshot())
        self.save()
        self.stop.wait(POLL)

    def bring_up(self) -> bool:
        """Start each group of parts once the one before is ready. False: stopped, or a part
        not ready in ``ready_timeout`` s, or one that exited and may not be restarted."""
        groups = [
            [p for p in self.parts if p.role == "hub"],
            [p for p in self.parts if p.role == "world"],
            [p for p in self.parts if p.role == "agent"],
            [p for p in self.parts if p.role == "daemon"],
        ]
        for group in (g for g in groups if g):
            for p in group:
                self.start(p)
            deadline = time.monotonic() + self.ready_timeout
            while not all(p.ready for p in group):
                if self.stop.is_set():
                    return False
                now = time.monotonic()
                for p in group:
                    if self._reap(p) and not p.respawn:
                        self.failure = f"{p.name} exited (code {p.exit_code}) while starting"
                        return False
                    if p.respawn:
                        self._respawn(p, now)
                    if not p.ready and (p.running() or not p.argv):
                        p.ready = self._ready(p)
                waiting = [p.name for p in group if not p.ready]
                self.waiting_for = ", ".join(waiting)
                if now > deadline:
                    self.failure = (
                        f"{self.waiting_for} not ready after {self.ready_timeout:.0f} s "
                        "(a loaded machine may need a longer --ready-timeout)"
                    )
                    return False
                self._tick()
        self.waiting_for = ""
        self.ready_s = time.monotonic() - self.t0
        self.stage = "waiting"
        log.info("lab up in %.1f s", self.ready_s)
        return True

    def supervise(self) -> None:
        """Until the daemon exits (the job's end), the world exits, or ``stop``."""
        daemon = self.parts[-1]
        while not self.stop.is_set():
            now = time.monotonic()
            self._handle_commands()
            for p in self.parts:
                if not p.ready and p.running():  # a restarted part: ready again when seen
                    p.ready = self._ready(p)
                if not self._reap(p) and p.restart_at is None:
                    continue
                if p is daemon:
                    self.job_ended = True
                    return
                if p.role == "world":
                    self.failure = f"the world exited (code {p.exit_code}; see {p.log_path})"
                    return
                self._respawn(p, now)
            if self.stage == "waiting" and self._released():
                self.stage = "running"
                self.resumed_at = time.monotonic()
            self._tick()

    def _released(self) -> bool:
        snap = self._snap
        return snap is not None and snap.estop == "released"

    def _handle_commands(self) -> None:
        with self._cmd_lock:
            words, self.commands = self.commands, []
        for word in words:
            result = self.watch.put(word, reason="the operator, from fleet up's console")
            if result is not None:
                from controller.runtime.estop import describe_put, exit_status

                # refused, unconfirmed or not durable (a holder cannot keep it): a warning
                level = logging.INFO if exit_status(result) == 0 else logging.WARNING
                log.log(level, "%s", describe_put(word, result))

    def shut_down(self) -> None:
        """The e-stop first (every robot stopped), then the daemon, the agents, the world, the
        hub: each SIGTERM, killed after STOP_WAIT s."""
        self.stage = "stopping"
        self.stopped_at = time.monotonic()
        if self.watch.bus is not None:
            try:
                result = self.watch.put("estop", "the lab is stopping", timeout=ESTOP_AT_STOP)
                self.final_estop = result
                if result and result["agents_missing"]:
                    log.warning("e-stop at the end NOT confirmed by %s", result["agents_missing"])
            except Exception as exc:  # noqa: BLE001 - stopping goes on: watchdogs stop robots
                log.warning("e-stop at the end failed: %s", exc)
        order = ["daemon", "agent", "world", "hub"]
        for role in order:
            group = [p for p in self.parts if p.role == role and p.running()]
            for p in group:
                p.proc.send_signal(signal.SIGCONT)
                p.proc.send_signal(signal.SIGTERM)
            for p in group:
                try:
                    p.proc.wait(timeout=STOP_WAIT)
                except subprocess.TimeoutExpired:
                    log.warning("%s did not stop in %.0f s: killed", p.name, STOP_WAIT)
                    p.proc.kill()
                    p.proc.wait()
                if p.exit_code is None:
                    p.exit_code = p.proc.returncode
        self.watch.close()
        self.stage = "ended"


def new_run_dir(cfg: FleetConfig) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    path = Path(cfg.log.dir) / f"{cfg.fleet.name}-lab-{stamp}"
    n = 1
    while path.exists():
        n += 1
        path = Path(cfg.log.dir) / f"{cfg.fleet.name}-lab-{stamp}-{n}"
    path.mkdir(parents=True)
    return path.resolve()  # the state file names it for tools started elsewhere
