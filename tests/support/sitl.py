"""ArduPilot's own Rover firmware (SITL) as a test peer: start it, watch it on a second link.

The firmware is not part of the repository: it is ``<repo>/../shared/sitl/ardurover`` (CI copies
``shared/`` beside its clean clone; a user's clone has none, and the tests skip saying so). Each
vehicle runs on 127.0.0.1 only, in a scratch folder of its own, on its own instance ``-I N``
(SERIAL0 = TCP 5760 + 10 N, where the project's driver connects; SERIAL1 = TCP 5762 + 10 N, where
the ``Monitor`` reads the firmware's own LOCAL_POSITION_NED and HEARTBEAT), and is killed by its
pid in ``stop`` (call it in a ``finally``).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil  # noqa: E402

from controller import wire  # noqa: E402
from controller.replay.membus import MemoryBus  # noqa: E402
from drivers.agent import Agent  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SITL_DIR = REPO.parent / "shared" / "sitl"
BINARY = SITL_DIR / "ardurover"
# frame -> (--model, defaults files layered over rover.parm)
FRAMES = {
    "rover": ("rover", ("rover.parm",)),
    "rover-skid": ("rover-skid", ("rover.parm", "rover-skid.parm")),
    "rover-omni3mecanum": ("rover-omni3mecanum", ("rover.parm", "rover-omni3mecanum.parm")),
}
ROVER_GUIDED, ROVER_HOLD = 15, 4
MONITOR_SYSTEM = 253  # the monitor's MAVLink system id: not the GCS the failsafe counts (255)
MONITOR_HZ = 25.0  # Hz of LOCAL_POSITION_NED asked on the monitor's link
CMD_TTL = 0.5  # s, the agent's watchdog
SPEED = 0.4  # m/s commanded
STOPPED = 0.05  # m/s: stopped
STEP = 0.05  # s between agent steps (20 Hz, the agent's rate floor in fleet driver)


def missing_reason() -> str | None:
    """Why the SITL tier cannot run here (None: it can)."""
    if not BINARY.is_file():
        return f"ArduRover SITL firmware not found at {BINARY} (a clone without ../shared/sitl)"
    if not os.access(BINARY, os.X_OK):
        return f"{BINARY} is not executable"
    return None


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def listening(port: int) -> bool:
    """Whether a TCP socket listens on ``port`` (Linux /proc/net/tcp, state 0A)."""
    try:
        lines = Path("/proc/net/tcp").read_text().splitlines()[1:]
    except OSError:
        return False
    want = f":{port:04X}"
    return any(f[1].endswith(want) and f[3] == "0A" for f in (ln.split() for ln in lines))


def free_instances(n: int, first: int = 20) -> list[int]:
    """``n`` SITL instance numbers whose TCP ports (5760..5763 + 10 N) and RC-in UDP port
    (5501 + 10 N) are free now, from a per-process start so parallel sessions rarely collide."""
    out: list[int] = []
    start = first + (os.getpid() % 97)
    for k in range(400):
        i = first + (start - first + k) % 400
        tcp = all(_port_free(5760 + 10 * i + d) for d in range(4))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
            try:
                u.bind(("127.0.0.1", 5501 + 10 * i))
                udp = True
            except OSError:
                udp = False
        if tcp and udp:
            out.append(i)
            if len(out) == n:
                return out
    raise RuntimeError("no free SITL instance ports")


class Sitl:
    """One ArduRover SITL process (``--speedup 1``, fresh parameters ``-w``)."""

    def __init__(self, frame: str, instance: int, extra_defaults: tuple[str, ...] = ()):
        model, parms = FRAMES[frame]
        self.frame = frame
        self.instance = instance
        self.port = 5760 + 10 * instance  # SERIAL0: the driver's
        self.monitor_port = 5762 + 10 * instance  # SERIAL1: the monitor's
        self.url = f"tcp:127.0.0.1:{self.port}"
        self.workdir = Path(tempfile.mkdtemp(prefix=f"sitl-{frame}-"))
        defaults = [str(SITL_DIR / p) for p in parms] + list(extra_defaults)
        self.cmd = [
            str(BINARY),
            "--model",
            model,
            "--speedup",
            "1",
            "--defaults",
            ",".join(defaults),
            "--sim-address=127.0.0.1",
            f"-I{instance}",
            "-w",
        ]
        self.proc: subprocess.Popen | None = None
        self.started = math.nan

    def start(self) -> Sitl:
        self._log = open(self.workdir / "sitl.log", "w")  # noqa: SIM115 - closed in stop
        self.proc = subprocess.Popen(
            self.cmd,
            cwd=self.workdir,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        self.started = time.monotonic()
        return self

    def wait_listening(self, timeout: float = 20.0) -> None:
        """Until SERIAL0 listens (read from /proc/net/tcp: no connection is made, the firmware
        boots on the first one, which must be the driver's)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc is not None and self.proc.poll() is not None:
                raise RuntimeError(f"SITL exited with {self.proc.returncode}: {self.tail()}")
            if listening(self.port):
                return
            time.sleep(0.05)
        raise RuntimeError(f"SITL {self.frame} not serving {self.url} in {timeout} s")

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def kill(self) -> None:
        """SIGKILL by pid (the vehicle vanishes without a word: a cut link)."""
        if self.alive():
            assert self.proc is not None
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait(5)

    def stop(self) -> None:
        if self.alive():
            assert self.proc is not None
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        if getattr(self, "_log", None) is not None:
            self._log.close()
        shutil.rmtree(self.workdir, ignore_errors=True)

    def tail(self, n: int = 15) -> str:
        try:
            lines = (self.workdir / "sitl.log").read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(lines[-n:])


@dataclass(frozen=True)
class Sample:
    t: float  # monotonic s when received
    boot: float  # s, the firmware's time_boot_ms
    x: float  # m north
    y: float  # m east
    vx: float  # m/s north
    vy: float  # m/s east

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


class Monitor:
    """The firmware's own view on SERIAL1: LOCAL_POSITION_NED, ATTITUDE and HEARTBEAT, read by a
    thread of this object (its own pymavlink connection, system id ``MONITOR_SYSTEM``)."""

    def __init__(self, sitl: Sitl):
        self.sitl = sitl
        self.samples: deque[Sample] = deque(maxlen=20000)
        self.mode: int | None = None
        self.armed = False
        self.yaw: float | None = None  # rad, NED
        self.heartbeats = 0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.conn = mavutil.mavlink_connection(
            f"tcp:127.0.0.1:{sitl.monitor_port}",
            source_system=MONITOR_SYSTEM,
            source_component=191,
            retries=0,
        )
        # the vehicle gone: stop reading (pymavlink would print on every read of the closed socket)
        self.conn.handle_eof = self.conn.handle_disconnect = self._stop.set
        self._thread = threading.Thread(target=self._run, name=f"monitor-{sitl.frame}", daemon=True)
        self._thread.start()

    def _ask(self) -> None:
        for msg_id in (32, 30):  # LOCAL_POSITION_NED, ATTITUDE
            self.conn.mav.command_long_send(1, 1, 511, 0, msg_id, 1e6 / MONITOR_HZ, 0, 0, 0, 0, 0)

    def _run(self) -> None:
        next_ask = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if not self.samples and now >= next_ask:  # until the position streams
                try:
                    self._ask()
                except OSError:
                    return
                next_ask = now + 2.0
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.05)
            except (OSError, ConnectionError):
                return
            if m is None:
                continue
            kind = m.get_type()
            t = time.monotonic()
            if kind == "LOCAL_POSITION_NED":
                with self._lock:
                    self.samples.append(Sample(t, m.time_boot_ms / 1e3, m.x, m.y, m.vx, m.vy))
            elif kind == "ATTITUDE":
                self.yaw = m.yaw
            elif kind == "HEARTBEAT" and m.get_srcComponent() == 1 and m.autopilot == 3:
                self.mode = m.custom_mode
                self.armed = bool(m.base_mode & 128)
                self.heartbeats += 1

    def since(self, t: float) -> list[Sample]:
        with self._lock:
            return [s for s in self.samples if s.t >= t]

    def last(self) -> Sample | None:
        with self._lock:
            return self.samples[-1] if self.samples else None

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        try:
            self.conn.close()
        except OSError:
            pass


def wait_until(pred, timeout: float, what: str, step=None, every: float = 0.02) -> float:
    """Poll ``pred`` (calling ``step()`` between polls) until true; returns the monotonic time
    it became true; raises AssertionError naming ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        if step is not None:
            step()
        if pred():
            return time.monotonic()
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(every)


class Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@dataclass
class Vehicle:
    rid: str
    sitl: Sitl
    robot: Any = None
    driver: Any = None
    agent: Agent | None = None
    bus: MemoryBus = field(default_factory=lambda: MemoryBus("t"))
    monitor: Monitor | None = None
    connect_s: float = math.nan
    error: BaseException | None = None
    seq: int = 0
    epoch: int = 0

    def log(self, lines: list[str]) -> list[str]:
        return [ln for ln in lines if ln.startswith(f"{self.rid}:") or f"'{self.rid}'" in ln]

    def step(self) -> None:
        assert self.agent is not None
        self.agent.step(time.time())

    def command(self, vx: float, wz: float = 0.0) -> None:
        self.seq += 1
        now = time.time()
        cmd = wire.Twist2D(t=now, seq=self.seq, vx=vx, wz=wz, ttl=CMD_TTL)
        self.bus.deliver("robot_cmd", cmd, id=self.rid)
        self.step()

    def estop(self, engaged: bool) -> None:
        self.epoch += 1
        msg = wire.EStop(t=time.time(), engaged=engaged, source="test", epoch=self.epoch)
        self.bus.deliver("estop", msg)
        self.step()

    def drive(self, vx: float, wz: float, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.command(vx, wz)
            time.sleep(STEP)

    def speed(self) -> float:
        s = self.monitor.last() if self.monitor else None
        return math.inf if s is None else s.speed

    def steady(self, speed: float = SPEED, timeout: float = 10.0) -> None:
        """Command ``speed`` straight on until the firmware reports it for 0.5 s."""

        def at_speed() -> bool:
            recent = self.monitor.since(time.monotonic() - 0.5)
            return len(recent) >= 5 and all(abs(s.speed - speed) < 0.06 for s in recent)

        wait_until(
            at_speed,
            timeout,
            f"{self.rid} at {speed} m/s",
            step=lambda: self.command(speed),
            every=STEP,
        )


def settle(v: Vehicle) -> None:
    """Let the watchdog stop it and the vehicle come to rest."""
    wait_until(lambda: v.speed() < STOPPED, 8, f"{v.rid} at rest", step=v.step)


def stop_time(v: Vehicle, t_stop: float) -> float:
    at = wait_until(
        lambda: any(s.speed < STOPPED for s in v.monitor.since(t_stop)),
        5,
        f"{v.rid} under {STOPPED} m/s",
        step=v.step,
        every=0.01,
    )
    first = next(s for s in v.monitor.since(t_stop) if s.speed < STOPPED)
    assert first.t <= at
    return first.t - t_stop
