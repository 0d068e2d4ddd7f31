"""MAVLink adapter: one ArduPilot Rover or PX4 rover behind the ``RobotDriver`` contract.

The robot's ``url`` is a pymavlink connection string: ``udpin:HOST:PORT`` (we listen, the vehicle
or a router sends to us), ``udpout:HOST:PORT`` (we send first), ``tcp:HOST:PORT`` or
``serial:DEVICE[:BAUD]``. Every driver of one url in a process shares one connection
(``LinkPool``): inbound messages are routed by source system id to their robot, and on a
``udpin`` port each robot's messages go only to the address that robot's packets came from
(pymavlink's own ``udpin`` write would send every packet to every peer it has seen).

Profiles:

- ``ardurover``: GUIDED; SET_POSITION_TARGET_LOCAL_NED in BODY_NED with the velocity + yaw rate
  mask, which ArduRover reads as signed forward speed + turn rate. vy is always sent as 0:
  GUIDED never moves sideways, so the robot is differential to the planner.
- ``px4``: OFFBOARD; body vx, vy and yaw rate (holonomic for an omni/mecanum rover). PX4 only
  accepts OFFBOARD after a setpoint stream, so ``connect`` streams zero setpoints for
  ``PX4_STREAM_BEFORE_OFFBOARD`` s first, and the driver keeps streaming while connected.

Time: every timeout and rate runs on the injected ``clock`` (s). Waiting inside ``connect`` goes
through ``idle(seconds)``; the default blocks on the socket for that long (real time, matching
the default ``time.monotonic`` clock). A lockstep dry run passes its sim clock and an ``idle``
that advances the sim. Nothing ever blocks without a timeout; ``poll``, ``send``, ``health`` and
``stop`` never block.

Keepalive: our HEARTBEAT goes to the robot at ``mavlink.heartbeat_hz`` (1 Hz by default: an
ArduRover's GCS failsafe ``FS_TIMEOUT`` must then be at least 3 s, three periods, or one late
heartbeat trips it) and the current setpoint is re-sent at
``SETPOINT_HZ`` from ``poll``/``send``/``health``, so the agent must call ``poll`` regularly (it
does, every tick). A command is held for its ``ttl``; after that the re-sent setpoint is zero.
When no vehicle HEARTBEAT arrived for the link timeout, the link is lost: ``health().ok`` is
false, ``send`` raises ``LinkLost`` and the keepalive sends no setpoint. The link timeout is
``link_timeout``, widened to ``HEARTBEAT_PERIODS`` heartbeat periods of what the vehicle really
sends (a vehicle that refuses a faster HEARTBEAT rate keeps 1 Hz: a 1 s timeout would flap), with
a warning when it widens (``link_timeout`` attribute).

Connect: the vehicle's HEARTBEAT; LOCAL_POSITION_NED and ATTITUDE at ``telemetry_hz``, stepped
down (``next_rate_down``) while the vehicle refuses (ArduPilot DENIES 50 Hz at its default
SCHED_LOOP_RATE, "Requested rate ... too fast") to ``telemetry_min_hz`` at worst, the rate
granted logged (``telemetry_hz`` attribute); its parameters (below); then its position estimate:
the first LOCAL_POSITION_NED (a fresh ArduPilot streams it ~42 s after its first connection and
refuses GUIDED and arming before), the wait logged every 5 s; then GUIDED / OFFBOARD and arming,
each asked again every REFUSED_RETRY s while refused, the vehicle's STATUSTEXT reason logged.
Each step is bounded by ``timeout`` (``fleet driver --connect-timeout``).

Stopping: ``stop()`` and ``close()`` read the link first and always send the zero setpoint, lost
or not (a vehicle that went quiet may still hear us, and a caller idle for longer than the link
timeout must not leave the vehicle on its last setpoint); ``close()`` then switches the vehicle
to HOLD when ``hold_on_close`` is set (fire and forget: close never waits). ``stop()`` (the
agent's e-stop, watchdog and lost-link stop) also switches the vehicle to its hold mode
(ArduPilot HOLD, PX4 AUTO.LOITER) as ``stop_hold`` says: "at_rest" (default) once the vehicle
reports it stopped, since its speed controller brakes in GUIDED while ArduRover's HOLD only cuts
the throttle (measured on ArduRover SITL from 0.4 m/s: ackermann 1.5-1.7 s braking in GUIDED,
3.5-3.7 s coasting in HOLD; skid 0.7 s either way); "now"; "off". ``disarm_on_stop`` disarms as
well. The next ``send`` asks for GUIDED / OFFBOARD (and arming) again. These mode changes are
fire and forget, re-asked by the keepalive until the HEARTBEAT shows them; ``health`` allows
MODE_SWITCH_GRACE s for them, and never asks a vehicle back from a mode its own failsafe chose.

The vehicle's own timeout: on connect the driver reads how long the vehicle keeps the last
setpoint once our stream stops, i.e. how far a rover drives on after this process dies
(``vehicle_timeout``): a PX4's ``COM_OF_LOSS_T``; an ArduRover's GUIDED target timeout
(``GUID_TIMEOUT``, a fixed 3 s in firmware without it) and its GCS failsafe (``FS_GCS_ENABLE``,
``FS_ACTION``, ``FS_TIMEOUT``, ``FS_GCS_TIMEOUT``), judged in drivers/mavlink/failsafe.py. When
it is unknown, unsafe (no GCS failsafe, a failsafe that drives home) or above
``max_vehicle_timeout``, connect warns, or refuses with ``strict`` (``fleet driver --strict``).
"""

from __future__ import annotations

import functools
import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

os.environ["MAVLINK20"] = "1"  # before pymavlink picks its dialect: MAVLink 2 messages needed


from controller.wire import PoseMeasurement, Twist2D  # noqa: E402
from drivers.base import ConnectTimeout, DriverError, LinkHealth, LinkLost, capabilities_of  # noqa: E402
from drivers.mavlink import convert as mc  # noqa: E402
from drivers.mavlink import failsafe  # noqa: E402
from drivers.mavlink.link import (  # noqa: E402
    AUTOPILOT_COMPONENT,
    LinkPool,
    MavLink,
)

if TYPE_CHECKING:
    from controller.config import RobotConfig

log = logging.getLogger(__name__)

SETPOINT_HZ = 10.0  # Hz, keepalive rate of the current setpoint (PX4 needs > 2 Hz)
HEARTBEAT_PERIOD = 1.0  # s, our GCS heartbeat by default (``[robots.mavlink] heartbeat_hz``)
PX4_STREAM_BEFORE_OFFBOARD = 1.2  # s of setpoints before asking for OFFBOARD (PX4 wants >= 1 s)
COMMAND_RETRY = 0.5  # s before a COMMAND_LONG without an ACK is sent again
POSE_QUEUE = 1024
PAIR_WINDOW = 0.1  # s: LOCAL_POSITION_NED and ATTITUDE closer than this make one pose
HEARTBEAT_PERIODS = 2.5  # the link timeout is at least this many vehicle heartbeat periods
DEFAULT_VEHICLE_HEARTBEAT = 1.0  # s, MAVLink's heartbeat period when the rate is not ours to set
PARAM_READ_TIMEOUT = 2.0  # s at most for reading one vehicle parameter on connect
REFUSED_RETRY = 1.0  # s before a refused mode change or arming is asked again during connect
ESTIMATE_LOG_EVERY = 5.0  # s between "waiting for the vehicle's position estimate" log lines
MODE_SWITCH_GRACE = 3.0  # s a mode / arming change we asked for may take before health fails
AT_REST = 0.05  # m/s: a stopped vehicle at or under this speed is at rest (stop_hold "at_rest")
HOLD_AFTER = 3.0  # s after a stop when "at_rest" asks for HOLD anyway (no telemetry, still rolling)
# Hz: the telemetry rates tried, fastest first, when the vehicle refuses the configured one
TELEMETRY_LADDER = (400.0, 200.0, 100.0, 50.0, 40.0, 30.0, 25.0, 20.0, 15.0, 10.0, 5.0, 2.0, 1.0)
STATUSTEXT_KEEP = 32  # the vehicle's last STATUSTEXT lines kept (its reasons for a refusal)
STATUSTEXT_CHUNK = 50  # chars of one STATUSTEXT; a longer text comes in chunks of one id


def next_rate_down(hz: float) -> float:
    """The next telemetry rate to try after ``hz`` Hz was refused: the next lower rung of
    ``TELEMETRY_LADDER`` (half of ``hz`` below the ladder)."""
    for rung in TELEMETRY_LADDER:
        if rung < hz - 1e-9:
            return rung
    return hz / 2.0


DEFAULT_POOL = LinkPool()


def _locked(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run a driver method under the driver's lock."""

    @functools.wraps(method)
    def wrapper(self: MavlinkDriver, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)

    return wrapper


@dataclass
class _Setpoint:
    vx: float = 0.0  # FRD m/s
    vy: float = 0.0  # FRD m/s (right)
    yaw_rate: float = 0.0  # rad/s clockwise
    until: float = math.inf  # driver clock time after which it decays to zero


class MavlinkDriver:
    """``RobotDriver`` for a MAVLink rover (profiles ``ardurover`` and ``px4``)."""

    def __init__(
        self,
        cfg: RobotConfig,
        *,
        clock: Callable[[], float] = time.monotonic,
        idle: Callable[[float], None] | None = None,
        pool: LinkPool | None = None,
        strict: bool = False,
        keepalive_thread: bool = False,
    ):
        """``strict``: refuse to connect when the vehicle's own setpoint timeout cannot be read or
        is longer than ``max_vehicle_timeout`` (otherwise a warning). ``keepalive_thread`` (real
        time only, e.g. ``fleet driver``): once connected, a thread of the driver services the
        link every ``1 / SETPOINT_HZ`` s as well, so the heartbeat and setpoint keepalive go on
        while the caller is busy elsewhere (an agent querying the e-stop latch for 2 s would
        otherwise let a PX4 with ``COM_OF_LOSS_T`` = 1 s fall to HOLD right after connect)."""
        if cfg.profile not in ("ardurover", "px4"):
            raise DriverError(f"robot {cfg.id!r}: unknown MAVLink profile {cfg.profile!r}")
        if not cfg.url:
            raise DriverError(f"robot {cfg.id!r}: a MAVLink robot needs a url")
        self.cfg = cfg
        self.robot_id = cfg.id
        self.profile = cfg.profile
        self.system_id = cfg.system_id
        self.gcs_id = cfg.gcs_system_id
        self.heartbeat_period = 1.0 / cfg.mavlink.heartbeat_hz  # s, our GCS heartbeat
        self.capabilities = capabilities_of(cfg)
        self._clock = clock
        self._idle = idle
        self._pool = pool or DEFAULT_POOL
        self._link: MavLink | None = None
        self._lock = threading.RLock()  # public calls vs. ticks from other drivers' threads
        self._connected = False
        self._closed = False
        self._t0 = clock()
        self._last_heard: float | None = None
        self._mode: int | None = None
        self._armed = False
        self._autopilot: int | None = None
        self._wall_deadline = math.inf
        self._acks: dict[int, int] = {}
        self._poses: deque[PoseMeasurement] = deque(maxlen=POSE_QUEUE)
        self._seq = 0
        self._lpn: Any = None
        self._att: Any = None
        self._boot_offset: float | None = None
        self._last_boot = -1.0
        self._setpoint = _Setpoint()
        self._last_sp_sent = -math.inf
        self._last_hb_sent = -math.inf
        self._streaming = False
        self._lost_logged = False
        self.strict = strict
        self._hb_assumed: float | None = None  # s, the heartbeat period we asked for / assume
        self._hb_gaps: deque[float] = deque(maxlen=5)  # s between the last vehicle heartbeats
        self._widened_logged = False
        self._params: dict[str, float] = {}
        # s the vehicle keeps our last setpoint by itself (PX4 COM_OF_LOSS_T; ArduRover its
        # GUIDED timeout or GCS failsafe), as read on connect; None: unknown
        self.vehicle_timeout: float | None = None
        self.vehicle_params: dict[str, float] = {}  # the ArduRover failsafe parameters read
        self.counters = {"setpoints": 0, "poses": 0, "unrouted": 0}
        self._keepalive = keepalive_thread
        # the LOCAL_POSITION_NED / ATTITUDE rate the vehicle granted (Hz), set on connect
        self.telemetry_hz: float | None = None
        self.statustext: deque[tuple[float, int, str]] = deque(maxlen=STATUSTEXT_KEEP)
        self._st_chunks: dict[int, list[str]] = {}
        self._estimate = False  # a LOCAL_POSITION_NED arrived: the vehicle has a position
        # e-stop / watchdog: the vehicle asked into its braking mode (and disarmed if configured)
        self.braking = False
        self._hold = False  # while braking: the hold mode is wanted now (stop_hold)
        self._braked_at = -math.inf  # when the stop came (driver clock)
        self._speed: tuple[float, float] | None = None  # (clock s, m/s) of the last position
        self._state_asked_at = -math.inf  # when the mode / arming now wanted was first asked
        self._mode_sent = -math.inf
        self._arm_sent = -math.inf
        self._ka_stop = threading.Event()
        self._ka_thread: threading.Thread | None = None

    # ------------------------------------------------------------------ contract

    @_locked
    def connect(self, timeout: float) -> None:
        """Wait for the vehicle's HEARTBEAT, request telemetry, set the mode and arm.

        ``timeout`` (s, driver clock) bounds each handshake step; raises ConnectTimeout naming
        the url and system id when the vehicle does not answer, DriverError when it refuses.
        """
        if self._closed:
            raise DriverError(f"robot {self.robot_id!r}: connect after close")
        if self._connected:
            return
        self._last_heard = self._mode = self._autopilot = None
        self._armed = self._streaming = self._estimate = self.braking = self._hold = False
        self._speed = None
        self._state_asked_at = -math.inf
        self._acks.clear()
        self._params.clear()
        self._hb_gaps.clear()
        self._hb_assumed = None
        # a frozen injected clock must not hang us: a generous wall-clock bound as well
        self._wall_deadline = time.monotonic() + 6.0 * timeout + PX4_STREAM_BEFORE_OFFBOARD + 5.0
        link = self._pool.acquire(self.cfg.url, self.gcs_id)
        link.register(self.system_id, self._tick)
        self._link = link
        try:
            self._handshake(timeout)
        except BaseException:
            self._release()
            raise
        self._connected = True
        log.info("%s: connected to system %d on %s", self.robot_id, self.system_id, self.cfg.url)
        if self._keepalive and self._ka_thread is None:
            self._ka_stop.clear()
            self._ka_thread = threading.Thread(
                target=self._keepalive_loop, name=f"mavlink-keepalive-{self.robot_id}", daemon=True
            )
            self._ka_thread.start()

    def _keepalive_loop(self) -> None:
        """Service the link (our heartbeat, the setpoint keepalive, the inbox) every
        ``1 / SETPOINT_HZ`` s until close."""
        while not self._ka_stop.wait(1.0 / SETPOINT_HZ):
            if not self._lock.acquire(timeout=0.05):  # the caller is in a call: it services
                continue
            try:
                link = self._link
                if link is not None and self._connected:
                    link.service(self.system_id)
            except Exception:  # noqa: BLE001 - the keepalive must outlive a bad packet
                log.exception("%s: keepalive failed", self.robot_id)
            finally:
                self._lock.release()

    @_locked
    def send(self, cmd: Twist2D) -> None:
        """Command a body-frame FLU velocity (m/s, m/s, rad/s) held for ``cmd.ttl`` s."""
        if not (math.isfinite(cmd.vx) and math.isfinite(cmd.vy) and math.isfinite(cmd.wz)):
            raise ValueError(f"robot {self.robot_id!r}: non-finite command {cmd}")
        self._require_link()
        now = self._service()
        if self._lost(now):
            raise LinkLost(self._lost_detail(now))
        vx, vy, yaw_rate = mc.flu_to_frd(cmd.vx, cmd.vy, cmd.wz)  # vy: 0 for diff (agent gate)
        self._setpoint = _Setpoint(vx, vy, yaw_rate, now + cmd.ttl)
        if self.braking:  # a command after an e-stop / watchdog stop: back to GUIDED / OFFBOARD
            self.braking = self._hold = False
            self._state_asked_at = now
            log.info(
                "%s: resuming: asking system %d for %s",
                self.robot_id,
                self.system_id,
                mc.mode_name(self.profile, self._wanted_mode()),
            )
            self._ensure_state(now, force=True)
        self._send_setpoint(now)

    @_locked
    def poll(self) -> list[PoseMeasurement]:
        """World-frame poses built from LOCAL_POSITION_NED + ATTITUDE since the last call."""
        if self._link is None:
            return []
        self._service()
        out = list(self._poses)
        self._poses.clear()
        return out

    @_locked
    def stop(self) -> None:
        """Zero setpoint now (and for the keepalive), then the vehicle's hold mode (ArduPilot
        HOLD, PX4 AUTO.LOITER) as ``stop_hold`` says: "at_rest" once its telemetry says it
        stopped (the speed controller brakes harder than HOLD, which only cuts the throttle on
        an ArduRover) or HOLD_AFTER s, "now" at once, "off" never; with ``disarm_on_stop``
        disarmed too. Mode and arming are re-asked by the keepalive until the vehicle reports
        them; the next ``send`` asks for GUIDED / OFFBOARD (and arming) again. Never raises,
        never blocks.

        The link is read first (the caller may have been idle for longer than the link
        timeout while the vehicle kept talking), and the zero goes out even when the link looks
        lost: a vehicle that went quiet may still hear us."""
        self._stop(brake=True)

    def _stop(self, brake: bool) -> None:
        self._setpoint = _Setpoint()
        if self._link is None or not self._connected:
            return
        try:
            now = self._service()
            self._lost(now)  # log the link's state; the zero goes out either way
            self._send_setpoint(now)
            m = self.cfg.mavlink
            if brake and (m.stop_hold != "off" or m.disarm_on_stop) and not self.braking:
                self.braking = True
                self._hold = m.stop_hold == "now"
                self._braked_at = self._state_asked_at = now
                hold = mc.mode_name(self.profile, self._hold_mode())
                log.info(
                    "%s: stop: zero setpoint%s%s",
                    self.robot_id,
                    {"now": f", {hold}", "at_rest": f", {hold} once at rest"}.get(m.stop_hold, ""),
                    ", disarm" if m.disarm_on_stop else "",
                )
            if self.braking:
                self._ensure_state(now, force=True)
        except Exception:  # noqa: BLE001 - stop must never raise
            log.exception("%s: stop failed", self.robot_id)

    @_locked
    def health(self) -> LinkHealth:
        """Lost when no HEARTBEAT for ``link_timeout``; not ok either when the vehicle left the
        mode we put it in (e.g. a failsafe HOLD) or disarmed although ``arm`` is set."""
        if self._closed:
            return LinkHealth(False, "closed", self._last_heard)
        if not self._connected:
            return LinkHealth(False, "not connected", self._last_heard)
        now = self._service()
        if self._lost(now):
            return LinkHealth(False, self._lost_detail(now), self._last_heard)
        want = self._wanted_mode()
        switching = now - self._state_asked_at < MODE_SWITCH_GRACE  # our own change under way
        if self._mode != want:
            got = mc.mode_name(self.profile, self._mode or 0)
            if switching:
                return LinkHealth(True, f"switching {got} to {mc.mode_name(self.profile, want)}",
                                  self._last_heard)  # fmt: skip
            return LinkHealth(
                False,
                f"vehicle in {got}, expected {mc.mode_name(self.profile, want)}",
                self._last_heard,
            )
        if self._want_armed() and not self._armed:
            if switching:
                return LinkHealth(True, "arming", self._last_heard)
            return LinkHealth(False, "vehicle disarmed", self._last_heard)
        return LinkHealth(True, "", self._last_heard)

    @_locked
    def close(self) -> None:
        """Zero the robot and release the link. Idempotent."""
        if self._closed:
            return
        self._stop_keepalive()
        self._stop(brake=False)  # the mode on close: hold_on_close's
        if self.cfg.hold_on_close and self._link is not None and self._connected:
            try:
                self._send_hold()
            except Exception:  # noqa: BLE001 - close must never raise
                log.exception("%s: HOLD on close failed", self.robot_id)
        self._closed = True
        self._connected = False
        self._release()

    # ------------------------------------------------------------------ internals

    def _stop_keepalive(self) -> None:
        thread, self._ka_thread = self._ka_thread, None
        if thread is not None:
            self._ka_stop.set()  # it waits on our lock at most 0.05 s, then sees this
            thread.join(timeout=2.0)

    def _release(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            link.unregister(self.system_id)
            self._pool.release(link)

    def _require_link(self) -> MavLink:
        if self._link is None or not self._connected:
            raise DriverError(f"robot {self.robot_id!r}: not connected")
        return self._link

    def _wanted_mode(self) -> int:
        """The mode the vehicle should be in: its hold mode while braking once ``stop_hold``
        wants it, else GUIDED (ArduRover) / OFFBOARD (PX4)."""
        if self.braking and self._hold:
            return self._hold_mode()
        return mc.ROVER_GUIDED if self.profile == "ardurover" else mc.PX4_OFFBOARD

    def _hold_mode(self) -> int:
        return mc.ROVER_HOLD if self.profile == "ardurover" else mc.PX4_HOLD

    def _at_rest(self, now: float) -> bool:
        """stop_hold "at_rest": whether the vehicle, stopped at ``_braked_at``, reported a
        speed of at most AT_REST since, or HOLD_AFTER s have passed."""
        if now - self._braked_at >= HOLD_AFTER:
            return True
        sp = self._speed
        return sp is not None and sp[0] > self._braked_at and sp[1] <= AT_REST

    def _want_armed(self) -> bool:
        """Whether the vehicle should be armed (``arm``, unless disarmed by a stop)."""
        return self.cfg.arm and not (self.braking and self.cfg.mavlink.disarm_on_stop)

    def _mode_params(self, mode: int) -> tuple[float, ...]:
        """DO_SET_MODE's params for a HEARTBEAT custom_mode of this profile."""
        if self.profile == "ardurover":
            return (mc.MODE_FLAG_CUSTOM, mode)
        return (mc.MODE_FLAG_CUSTOM, (mode >> 16) & 0xFF, (mode >> 24) & 0xFF)

    def _ensure_state(self, now: float, force: bool = False) -> None:
        """Once connected: ask (fire and forget, again every COMMAND_RETRY s) for the mode and
        arming state wanted until the vehicle's HEARTBEAT reports them. Disarming comes after
        the braking mode; arming after GUIDED / OFFBOARD."""
        if not (force or self.braking or now - self._state_asked_at < MODE_SWITCH_GRACE):
            return  # a resume the vehicle did not take (or its own failsafe): health reports it
        if self.braking and not self._hold and self.cfg.mavlink.stop_hold == "at_rest":
            # at rest, or out of GUIDED / OFFBOARD already (a failsafe): never asked back
            if self._at_rest(now) or self._mode != self._wanted_mode():
                self._hold = True
                self._state_asked_at = now
                force = True
                hold = mc.mode_name(self.profile, self._hold_mode())
                log.info(
                    "%s: %.2f s after the stop: %s", self.robot_id, now - self._braked_at, hold
                )
        want = self._wanted_mode()
        if self._mode != want:
            if force or now - self._mode_sent >= COMMAND_RETRY:
                self._mode_sent = now
                self._send_command(mc.CMD_DO_SET_MODE, self._mode_params(want))
            if not (self.braking and self.cfg.mavlink.disarm_on_stop):
                return
        armed = self._want_armed()
        if self.braking and self.cfg.mavlink.disarm_on_stop and self._armed:
            if force or now - self._arm_sent >= COMMAND_RETRY:
                self._arm_sent = now
                self._send_command(mc.CMD_COMPONENT_ARM_DISARM, (0.0,))
        elif armed and not self._armed and self._mode == want:
            if force or now - self._arm_sent >= COMMAND_RETRY:
                self._arm_sent = now
                self._send_command(mc.CMD_COMPONENT_ARM_DISARM, (1.0,))

    def _send_command(self, command: int, params: tuple[float, ...]) -> None:
        """One COMMAND_LONG, no ACK awaited."""
        p = list(params) + [0.0] * (7 - len(params))
        self._send(
            lambda mav: mav.command_long_encode(self.system_id, AUTOPILOT_COMPONENT, command, 0, *p)
        )

    @property
    def link_timeout(self) -> float:
        """s of vehicle silence before the link is lost: ``link_timeout``, at least
        ``HEARTBEAT_PERIODS`` periods of the heartbeats the vehicle really sends."""
        period = self._heartbeat_period()
        if period is None:
            return self.cfg.link_timeout
        wide = HEARTBEAT_PERIODS * period
        if wide > self.cfg.link_timeout and not self._widened_logged:
            self._widened_logged = True
            log.warning(
                "%s: system %d sends HEARTBEAT every %.2f s: link_timeout %.2f s widened to "
                "%.2f s (%.1f heartbeat periods)",
                self.robot_id,
                self.system_id,
                period,
                self.cfg.link_timeout,
                wide,
                HEARTBEAT_PERIODS,
            )
        return max(self.cfg.link_timeout, wide)

    def _heartbeat_period(self) -> float | None:
        """The vehicle's heartbeat period: the median of the last gaps seen (3 or more), else
        what we asked for (or MAVLink's 1 s when the vehicle refused), else unknown."""
        if len(self._hb_gaps) >= 3:
            gaps = sorted(self._hb_gaps)
            return gaps[len(gaps) // 2]
        return self._hb_assumed

    def _lost(self, now: float) -> bool:
        lost = self._last_heard is None or now - self._last_heard > self.link_timeout
        if lost and not self._lost_logged:
            log.warning("%s: %s", self.robot_id, self._lost_detail(now))
            self._lost_logged = True
        elif not lost and self._lost_logged:
            log.info("%s: link to system %d back", self.robot_id, self.system_id)
            self._lost_logged = False
        return lost

    def _lost_detail(self, now: float) -> str:
        ago = "ever" if self._last_heard is None else f"{now - self._last_heard:.2f} s"
        return (
            f"robot {self.robot_id!r}: link lost, no HEARTBEAT from system {self.system_id} "
            f"on {self.cfg.url} for {ago} (link timeout {self.link_timeout:.2f} s)"
        )

    def _wait(self, seconds: float) -> None:
        if self._idle is not None:
            self._idle(seconds)
        elif self._link is not None:
            self._link.wait(seconds)

    def _service(self) -> float:
        """Read and handle inbound messages, send due keepalives (for every driver on the
        link); returns the clock (s)."""
        link = self._link
        if link is not None:
            link.service(self.system_id)
        return self._clock()

    def _tick(self, blocking: bool) -> None:
        """Handle this robot's inbox and send its due heartbeat and setpoint keepalive."""
        if not self._lock.acquire(blocking=blocking):
            return
        try:
            link = self._link
            if link is None:
                return
            now = self._clock()
            for m in link.take(self.system_id):
                self._handle(m, now)
            if now - self._last_hb_sent >= self.heartbeat_period:
                self._send_heartbeat(now)
            if self._streaming and now - self._last_sp_sent >= 1.0 / SETPOINT_HZ:
                if not self._lost(now):
                    self._send_setpoint(now)
            if self._connected and not self._closed and not self._lost(now):
                self._ensure_state(now)
        finally:
            self._lock.release()

    def _handle(self, m: Any, now: float) -> None:
        kind = m.get_type()
        if kind == "HEARTBEAT":
            if m.get_srcComponent() != AUTOPILOT_COMPONENT or m.autopilot == mc.AUTOPILOT_INVALID:
                return
            if self._last_heard is not None and now > self._last_heard:
                self._hb_gaps.append(now - self._last_heard)
            self._last_heard = now
            self._mode = m.custom_mode
            self._armed = bool(m.base_mode & mc.MODE_FLAG_ARMED)
            self._autopilot = m.autopilot
        elif kind == "COMMAND_ACK":
            self._acks[m.command] = m.result
        elif kind == "PARAM_VALUE":
            name = m.param_id.decode() if isinstance(m.param_id, bytes) else str(m.param_id)
            if math.isfinite(m.param_value):
                self._params[name.rstrip("\x00")] = float(m.param_value)
        elif kind == "ATTITUDE":
            self._att = m
            self._try_pose(now)
        elif kind == "LOCAL_POSITION_NED":
            self._estimate = True
            self._speed = (now, math.hypot(m.vx, m.vy))
            self._lpn = m
            self._try_pose(now)
        elif kind == "STATUSTEXT":
            self._on_statustext(m, now)

    def _on_statustext(self, m: Any, now: float) -> None:
        """Keep the vehicle's text (chunks of one id joined); log warnings and worse."""
        text = m.text.decode(errors="replace") if isinstance(m.text, bytes) else str(m.text)
        text = text.rstrip("\x00")
        sid = getattr(m, "id", 0)
        if sid:
            parts = self._st_chunks.setdefault(sid, [])
            parts.append(text)
            if len(text) >= STATUSTEXT_CHUNK and len(parts) < 8:
                return  # more chunks to come
            text = "".join(self._st_chunks.pop(sid))
        self.statustext.append((now, m.severity, text))
        level = logging.WARNING if m.severity <= 4 else logging.DEBUG
        log.log(level, "%s: system %d says: %s", self.robot_id, self.system_id, text)

    def _texts_since(self, t: float) -> str:
        """The vehicle's STATUSTEXT lines since ``t`` (driver clock), joined."""
        return "; ".join(text for at, _, text in self.statustext if at >= t)

    def _try_pose(self, now: float) -> None:
        lpn, att = self._lpn, self._att
        if lpn is None or att is None:
            return
        if abs(lpn.time_boot_ms - att.time_boot_ms) > PAIR_WINDOW * 1000.0:
            return
        self._lpn = self._att = None
        boot = lpn.time_boot_ms / 1000.0
        if boot < self._last_boot - 1.0:  # the vehicle rebooted
            self._boot_offset = None
        self._last_boot = boot
        offset = now - boot
        if self._boot_offset is None or offset < self._boot_offset:
            self._boot_offset = offset
        x, y, theta = mc.ned_to_enu_pose(lpn.x, lpn.y, att.yaw)
        if not all(math.isfinite(v) for v in (x, y, theta)):
            return
        self._seq += 1
        self.counters["poses"] += 1
        self._poses.append(
            PoseMeasurement(
                t=boot + self._boot_offset,
                seq=self._seq,
                x=x,
                y=y,
                theta=theta,
                source=f"mavlink:{self.system_id}",
            )
        )

    def _send(self, build: Callable[[Any], Any]) -> bool:
        link = self._link
        if link is None:
            return False
        ok = link.send_to(self.system_id, build, self.gcs_id)
        if not ok:
            self.counters["unrouted"] += 1
        return ok

    def _send_heartbeat(self, now: float) -> None:
        self._last_hb_sent = now
        self._send(lambda mav: mav.heartbeat_encode(mc.TYPE_GCS, mc.AUTOPILOT_INVALID, 0, 0, 4))

    def _boot_ms(self, now: float) -> int:
        return int(max(0.0, now - self._t0) * 1000.0) & 0xFFFFFFFF

    def _send_setpoint(self, now: float) -> None:
        sp = self._setpoint
        if now > sp.until:
            sp = self._setpoint = _Setpoint()
        self._last_sp_sent = now
        self._streaming = True
        self.counters["setpoints"] += 1
        ms = self._boot_ms(now)
        self._send(
            lambda mav: mav.set_position_target_local_ned_encode(
                ms,
                self.system_id,
                AUTOPILOT_COMPONENT,
                mc.FRAME_BODY_NED,
                mc.MASK_VELOCITY_YAW_RATE,
                0.0,
                0.0,
                0.0,
                sp.vx,
                sp.vy,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                sp.yaw_rate,
            )
        )

    def _send_hold(self) -> None:
        """Ask the vehicle for HOLD once (no ACK awaited)."""
        if self.profile == "ardurover":
            params = (mc.MODE_FLAG_CUSTOM, mc.ROVER_HOLD, 0.0)
        else:
            params = (mc.MODE_FLAG_CUSTOM, mc.PX4_MAIN_AUTO, mc.PX4_SUB_AUTO_LOITER)
        p = list(params) + [0.0] * 4
        self._send(
            lambda mav: mav.command_long_encode(
                self.system_id, AUTOPILOT_COMPONENT, mc.CMD_DO_SET_MODE, 0, *p
            )
        )

    def _read_params(
        self, names: tuple[str, ...], timeout: float, optional: tuple[str, ...] = ()
    ) -> dict[str, float]:
        """Vehicle parameters by name (PARAM_REQUEST_READ for each not yet answered, re-asked
        every COMMAND_RETRY s) until all of ``names`` answered or ``timeout`` s; the
        ``optional`` ones (parameters older firmware lacks) get COMMAND_RETRY s more once
        ``names`` are in. Returns those answered."""
        wanted = names + optional
        for name in wanted:
            self._params.pop(name, None)
        deadline = self._clock() + timeout
        grace: float | None = None
        while True:
            for name in wanted:
                if name not in self._params:
                    pid = name.encode()
                    self._send(
                        lambda mav, pid=pid: mav.param_request_read_encode(
                            self.system_id, AUTOPILOT_COMPONENT, pid, -1
                        )
                    )
            retry_at = self._clock() + COMMAND_RETRY
            self._wait_until(
                lambda: all(n in self._params for n in wanted), min(deadline, retry_at)
            )
            now = self._clock()
            if all(n in self._params for n in names) and grace is None:
                grace = now + COMMAND_RETRY
            done = all(n in self._params for n in wanted) or (grace is not None and now >= grace)
            if done or now >= deadline or time.monotonic() > self._wall_deadline:
                return {n: self._params[n] for n in wanted if n in self._params}

    def _check_vehicle_timeout(self, timeout: float) -> None:
        """Read how long the vehicle keeps our last setpoint by itself (PX4 ``COM_OF_LOSS_T``;
        ArduRover ``FS_GCS_ENABLE``, ``FS_TIMEOUT``, ``FS_ACTION``, and ``FS_GCS_TIMEOUT``,
        ``GUID_TIMEOUT`` where the firmware has them: drivers/mavlink/failsafe.py) and warn, or
        refuse when ``strict``, when that is unsafe or above ``max_vehicle_timeout``."""
        limit = self.cfg.max_vehicle_timeout
        wait = min(timeout, PARAM_READ_TIMEOUT)
        if self.profile == "px4":
            name = mc.PX4_OFFBOARD_LOSS_PARAM
            verdict = failsafe.assess_px4(self._read_params((name,), wait).get(name), limit)
        else:
            self.vehicle_params = self._read_params(
                failsafe.ROVER_REQUIRED, wait, failsafe.ROVER_OPTIONAL
            )
            verdict = failsafe.assess_ardurover(self.vehicle_params, limit, self.heartbeat_period)
        self.vehicle_timeout = verdict.stop_after
        where = f"robot {self.robot_id!r}: system {self.system_id} on {self.cfg.url}"
        for note in verdict.notes:
            log.warning("%s %s", where, note)
        if not verdict.problems:
            return
        problem = f"{where} " + "; ".join(verdict.problems)
        if self.strict:
            raise DriverError(problem + " (refused: --strict)")
        log.warning("%s", problem)

    def _command(self, command: int, params: tuple[float, ...], timeout: float, what: str) -> None:
        """Send a COMMAND_LONG until its COMMAND_ACK arrives; raise if refused or unanswered."""
        p = list(params) + [0.0] * (7 - len(params))
        self._acks.pop(command, None)
        started = self._clock()
        deadline = started + timeout
        confirmation = 0
        while True:
            now = self._clock()

            def build(mav: Any, c: int = confirmation) -> Any:
                return mav.command_long_encode(self.system_id, AUTOPILOT_COMPONENT, command, c, *p)

            self._send(build)
            retry_at = now + COMMAND_RETRY
            while True:
                now = self._service()
                if command in self._acks:
                    result = self._acks.pop(command)
                    if result != mc.RESULT_ACCEPTED:
                        name = mc.RESULT_NAMES.get(result, str(result))
                        self._wait_until(lambda: False, self._clock() + 0.1)  # its reason
                        why = self._texts_since(started)
                        raise DriverError(
                            f"robot {self.robot_id!r}: system {self.system_id} on "
                            f"{self.cfg.url} refused {what}: {name}"
                            + (f" (vehicle: {why})" if why else "")
                        )
                    return
                if now >= deadline or time.monotonic() > self._wall_deadline:
                    raise ConnectTimeout(
                        f"robot {self.robot_id!r}: no COMMAND_ACK for {what} from system "
                        f"{self.system_id} on {self.cfg.url} within {timeout} s"
                    )
                if now >= retry_at:
                    break
                self._wait(min(0.02, deadline - now, retry_at - now))
            confirmation = min(confirmation + 1, 255)

    def _command_retrying(
        self, command: int, params: tuple[float, ...], timeout: float, what: str
    ) -> None:
        """``_command``, asked again every REFUSED_RETRY s while the vehicle refuses it (each
        refusal logged with the vehicle's STATUSTEXT reason) until ``timeout`` s."""
        deadline = self._clock() + timeout
        while True:
            try:
                self._command(command, params, max(0.0, deadline - self._clock()), what)
                return
            except ConnectTimeout:
                raise
            except DriverError as exc:
                now = self._clock()
                if now + REFUSED_RETRY >= deadline or time.monotonic() > self._wall_deadline:
                    raise
                log.warning("%s; asking again in %g s", exc, REFUSED_RETRY)
                self._wait_until(lambda: False, now + REFUSED_RETRY)

    def _negotiate_telemetry(self, timeout: float) -> float:
        """Ask LOCAL_POSITION_NED and ATTITUDE at ``telemetry_hz``; while the vehicle refuses,
        at the next lower rate (``next_rate_down``) down to ``telemetry_min_hz``. Returns the
        rate granted (Hz, logged); raises DriverError when even the floor is refused."""
        asked = float(self.cfg.telemetry_hz)
        floor = min(float(self.cfg.mavlink.telemetry_min_hz), asked)
        hz = asked
        while True:
            try:
                for msg_id, name in ((mc.MSG_LOCAL_POSITION_NED, "LOCAL_POSITION_NED"),
                                     (mc.MSG_ATTITUDE, "ATTITUDE")):  # fmt: skip
                    self._command(
                        mc.CMD_SET_MESSAGE_INTERVAL,
                        (msg_id, 1e6 / hz),
                        timeout,
                        f"SET_MESSAGE_INTERVAL {name} at {hz:g} Hz",
                    )
                break
            except ConnectTimeout:
                raise
            except DriverError as exc:
                lower = next_rate_down(hz)
                if lower < floor - 1e-9:
                    raise DriverError(
                        f"{exc}; refused every telemetry rate from {asked:g} Hz down to "
                        f"telemetry_min_hz {floor:g} Hz"
                    ) from exc
                log.info("%s: %s; asking %g Hz", self.robot_id, exc, lower)
                hz = lower
        level = logging.WARNING if hz < asked else logging.INFO
        log.log(level, "%s: system %d grants telemetry at %g Hz (asked %g Hz)",
                self.robot_id, self.system_id, hz, asked)  # fmt: skip
        return hz

    def _wait_estimate(self, timeout: float) -> None:
        """Wait up to ``timeout`` s for the vehicle's position estimate: its first
        LOCAL_POSITION_NED (an ArduPilot streams it only once its EKF has an origin, ~40 s after
        a fresh start; GUIDED and arming are refused before), logging the wait every
        ESTIMATE_LOG_EVERY s."""
        start = self._clock()
        deadline = start + timeout
        next_log = start + ESTIMATE_LOG_EVERY
        while not self._estimate:
            now = self._service()
            if self._estimate:
                break
            if now >= next_log:
                log.info("%s: waiting for the vehicle's position estimate: %.0f s",
                         self.robot_id, now - start)  # fmt: skip
                next_log += ESTIMATE_LOG_EVERY
            if now >= deadline or time.monotonic() > self._wall_deadline:
                why = self._texts_since(start)
                raise ConnectTimeout(
                    f"robot {self.robot_id!r}: no position estimate (LOCAL_POSITION_NED) from "
                    f"system {self.system_id} on {self.cfg.url} within {timeout} s"
                    + (f" (vehicle: {why})" if why else "")
                )
            self._wait(min(0.05, max(0.0, deadline - now)))
        if self._clock() - start > 1.0:
            log.info("%s: the vehicle's position estimate after %.1f s",
                     self.robot_id, self._clock() - start)  # fmt: skip

    def _wait_until(self, pred: Callable[[], bool], deadline: float) -> bool:
        while True:
            now = self._service()
            if pred():
                return True
            if now >= deadline or time.monotonic() > self._wall_deadline:
                return False
            self._wait(min(0.02, deadline - now))

    def _handshake(self, timeout: float) -> None:
        link = self._link
        assert link is not None
        self._send_heartbeat(self._clock())  # lets a udpout/tcp vehicle learn our address
        if not self._wait_until(lambda: self._last_heard is not None, self._clock() + timeout):
            raise ConnectTimeout(
                f"robot {self.robot_id!r}: no HEARTBEAT from system {self.system_id} on "
                f"{self.cfg.url} within {timeout} s"
            )
        want_ap = mc.AUTOPILOT_ARDUPILOT if self.profile == "ardurover" else mc.AUTOPILOT_PX4
        if self._autopilot != want_ap:
            raise DriverError(
                f"robot {self.robot_id!r}: system {self.system_id} on {self.cfg.url} is "
                f"autopilot {self._autopilot}, profile {self.profile!r} expects {want_ap}"
            )
        self._send_heartbeat(self._clock())  # the vehicle's address is known now
        self.telemetry_hz = self._negotiate_telemetry(timeout)
        hb = min(DEFAULT_VEHICLE_HEARTBEAT, self.cfg.link_timeout / 4.0)
        try:  # heartbeats often enough that link_timeout never flaps (vehicles default to 1 Hz)
            self._command(
                mc.CMD_SET_MESSAGE_INTERVAL,
                (mc.MSG_HEARTBEAT, 1e6 * hb),
                timeout,
                "SET_MESSAGE_INTERVAL HEARTBEAT",
            )
            self._hb_assumed = hb
        except DriverError as exc:
            self._hb_assumed = DEFAULT_VEHICLE_HEARTBEAT
            log.info("%s: %s; assuming %g s heartbeats", self.robot_id, exc, self._hb_assumed)
        self._hb_gaps.clear()  # gaps seen before the rate was set say nothing
        _ = self.link_timeout  # warns now if the vehicle's heartbeats widen it
        self._check_vehicle_timeout(timeout)
        self._wait_estimate(timeout)
        if self.profile == "ardurover":
            self._command_retrying(
                mc.CMD_DO_SET_MODE, (mc.MODE_FLAG_CUSTOM, mc.ROVER_GUIDED), timeout, "GUIDED"
            )
        else:
            self._setpoint = _Setpoint()
            start = self._clock()
            self._send_setpoint(start)  # the keepalive in _service streams from here on
            self._wait_until(lambda: False, start + PX4_STREAM_BEFORE_OFFBOARD)
            self._command_retrying(
                mc.CMD_DO_SET_MODE,
                (mc.MODE_FLAG_CUSTOM, mc.PX4_MAIN_OFFBOARD, 0),
                timeout,
                "OFFBOARD",
            )
        if self.cfg.arm:
            self._command_retrying(mc.CMD_COMPONENT_ARM_DISARM, (1.0,), timeout, "arming")
        want = self._wanted_mode()
        if not self._wait_until(
            lambda: self._mode == want and (self._armed or not self.cfg.arm),
            self._clock() + timeout,
        ):
            raise ConnectTimeout(
                f"robot {self.robot_id!r}: system {self.system_id} on {self.cfg.url} did not "
                f"report {mc.mode_name(self.profile, want)}{' and armed' if self.cfg.arm else ''}"
                f" within {timeout} s (it reports {mc.mode_name(self.profile, self._mode or 0)})"
            )
        self._streaming = True
        self._connected = True
