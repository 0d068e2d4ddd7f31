"""A MAVLink vehicle emulator backed by a sim world: one MAVLink system per robot on loopback UDP.

It behaves like the flight controller of a lab rover, enough to test the MAVLink adapter and to
run the whole MAVLink path in the dry run:

- HEARTBEAT at 1 Hz with the profile's autopilot (ArduPilot or PX4), MAV_TYPE_GROUND_ROVER, the
  current custom mode and the armed flag; LOCAL_POSITION_NED and ATTITUDE (NED, from the world's
  true pose) at the rates asked by MAV_CMD_SET_MESSAGE_INTERVAL (4 Hz until asked).
- COMMAND_ACK for MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_DO_SET_MODE and
  MAV_CMD_COMPONENT_ARM_DISARM (UNSUPPORTED for anything else). ``heartbeat_rate_fixed``: a
  HEARTBEAT interval is refused (UNSUPPORTED) and heartbeats stay at 1 Hz, like many vehicles.
- PARAM_REQUEST_READ by name, answered with PARAM_VALUE (``params()``); unknown names, and
  those in ``unanswered`` (older firmware), get no answer (as PX4 and ArduPilot do). A PX4
  answers ``COM_OF_LOSS_T`` (= ``offboard_loss_timeout``); an ArduRover ``FS_GCS_ENABLE``
  (``fs_gcs_enable``), ``FS_TIMEOUT`` (= ``gcs_timeout``), ``FS_ACTION`` (``fs_action``) and
  ``GUID_TIMEOUT`` (= ``target_timeout``), all as it behaves. (No ``FS_GCS_TIMEOUT``: the
  emulated failsafe acts ``gcs_timeout`` s after the last GCS heartbeat, where a real rover waits
  FS_GCS_TIMEOUT, or 2 s, then FS_TIMEOUT more: earlier, so a flapping failsafe shows here
  first.)
- ``ardurover``: GUIDED takes SET_POSITION_TARGET_LOCAL_NED with the velocity + yaw-rate mask as
  signed forward speed + turn rate (the lateral component is ignored), or velocity only as speed +
  heading; a mask with any velocity bit set ignores the velocity. A target older than
  ``target_timeout`` (3 s) stops the rover. The GCS failsafe (``fs_gcs_enable``): once a
  HEARTBEAT from the GCS system id has been seen, ``gcs_timeout`` s without one takes an armed
  rover to its ``fs_action``: 2 HOLD (the default), 1/3 RTL, 4 SMART_RTL (reported in the
  HEARTBEAT; the emulator does not drive them: any mode but GUIDED is a zero command), 0 none.
- ``px4``: OFFBOARD takes body vx, vy and yaw rate (holonomic; the world drops vy for a diff
  robot). DO_SET_MODE OFFBOARD is refused unless setpoints have streamed above 2 Hz for at least
  1 s; in OFFBOARD, ``offboard_loss_timeout`` s without a setpoint switches to HOLD (AUTO.LOITER).
- Not armed, or in any other mode: zero command.
- Like ArduPilot's firmware (SITL, NOTES.md): ``max_rate_hz`` refuses a faster telemetry
  interval (DENIED, with its STATUSTEXT "Requested rate ... too fast"); ``estimate_after`` (s
  after boot) sends no LOCAL_POSITION_NED before, and refuses GUIDED/OFFBOARD ("Flight mode change
  failed") and arming ("Arm: Need Position Estimate") before (FAILED, with the STATUSTEXT);
  ``arm_refusals``: the first N arming requests fail ("PreArm: Hardware safety switch").

Time: ``pump(now)`` does one non-blocking round (read inbound, apply failsafes and the command to
the world, send due telemetry) at time ``now`` (s) on the caller's clock; a lockstep dry run calls
it after each world step. ``start()`` runs the same in a background thread on ``clock``. The
world is stepped by its owner; pass ``world_lock`` to share a lock with it in threaded use.
Only loopback addresses are allowed.

Dry-run recipe (lockstep)::

    emus = start_emulators(world, cfg.robots, clock=sim_clock)   # one per driver = "mavlink"
    def advance(dt):                       # also the drivers' ``idle`` hook during connect
        for e in emus: e.pump(t)           # apply commands that arrived
        world.step(dt); t += dt
        for e in emus: e.pump(t)           # telemetry due at the new time
    driver = MavlinkDriver(robot_cfg, clock=sim_clock, idle=advance)

Telemetry goes out when due at a ``pump``, so poses arrive at min(requested rate, pump rate).
Loopback ``sendto`` puts the datagram in the receiver's buffer before it returns, so a command
sent before the sim's ``pump`` is always seen by it.
"""

from __future__ import annotations

import logging
import math
import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

os.environ["MAVLINK20"] = "1"  # before pymavlink picks its dialect

from pymavlink import mavutil  # noqa: E402

from controller.geometry import wrap_angle  # noqa: E402
from drivers.mavlink import convert as mc  # noqa: E402

if TYPE_CHECKING:
    from controller.config import RobotConfig
    from sim_backend.base import World

log = logging.getLogger(__name__)

DEFAULT_INTERVAL = 0.25  # s, telemetry period until a SET_MESSAGE_INTERVAL
STREAM_GAP = 0.5  # s: setpoints further apart than this (<= 2 Hz) break a PX4 stream
STREAM_MIN = 1.0  # s of stream PX4 wants before OFFBOARD
HEADING_GAIN = 2.0  # 1/s, ArduRover speed + heading mode: turn rate per rad of heading error
LOOPBACK = ("127.0.0.1", "localhost")


def vehicle_url(driver_url: str) -> str:
    """The emulator's connection string that answers a driver's ``url`` on loopback.

    ``udpin:H:P`` (the driver listens) -> ``udpout:127.0.0.1:P``; ``udpout:H:P`` -> ``udpin:H:P``;
    ``tcp:H:P`` -> ``tcpin:H:P``. Raises ValueError for other urls or non-loopback hosts.
    """
    scheme, _, rest = driver_url.partition(":")
    host, _, port = rest.rpartition(":")
    if not port.isdigit():
        raise ValueError(f"cannot emulate a vehicle for url {driver_url!r}: no port")
    if scheme == "udpin":
        return f"udpout:127.0.0.1:{port}"
    if host not in LOOPBACK:
        raise ValueError(f"the emulator only uses loopback, not {host!r} in {driver_url!r}")
    if scheme == "udpout":
        return f"udpin:{host}:{port}"
    if scheme == "tcp":
        return f"tcpin:{host}:{port}"
    raise ValueError(f"cannot emulate a vehicle for url {driver_url!r} (udpin, udpout, tcp)")


def _mavutil_v2() -> Any:
    if getattr(mavutil.mavlink, "WIRE_PROTOCOL_VERSION", "") != "2.0":
        os.environ["MAVLINK20"] = "1"
        mavutil.set_dialect("ardupilotmega")
    return mavutil


@dataclass(frozen=True)
class SetpointRecord:
    """One SET_POSITION_TARGET_LOCAL_NED as received (NED/FRD units: m/s, rad/s CW)."""

    t: float
    target_system: int
    frame: int
    type_mask: int
    vx: float
    vy: float
    vz: float
    yaw_rate: float


class VehicleEmulator:
    """One emulated MAVLink rover for ``robot_cfg`` (its ``system_id``, ``profile``,
    ``gcs_system_id``), driving robot ``robot_cfg.id`` of ``world``."""

    def __init__(
        self,
        world: World,
        robot_cfg: RobotConfig,
        bind: str | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        gcs_timeout: float = 5.0,
        target_timeout: float = 3.0,
        offboard_loss_timeout: float = 1.0,
        world_lock: threading.Lock | None = None,
        listener: Callable[[Any], None] | None = None,
        heartbeat_rate_fixed: bool = False,
        fs_gcs_enable: bool = True,
        fs_action: int = mc.ROVER_FS_ACTION_HOLD,
        unanswered: Iterable[str] = (),
        max_rate_hz: float = math.inf,
        estimate_after: float = 0.0,
        arm_refusals: int = 0,
    ):
        """``bind``: a pymavlink url for the vehicle side, or ``HOST:PORT`` of the driver's
        listening port (-> ``udpout``); default derived from ``robot_cfg.url``."""
        if robot_cfg.profile not in ("ardurover", "px4"):
            raise ValueError(f"robot {robot_cfg.id!r}: unknown profile {robot_cfg.profile!r}")
        if bind is None:
            url = vehicle_url(robot_cfg.url)
        elif ":" in bind and bind.split(":", 1)[0] in ("udpin", "udpout", "tcpin", "tcp"):
            url = bind
        else:
            url = f"udpout:{bind}"
        host = url.split(":")[1]
        if host not in LOOPBACK:
            raise ValueError(f"the emulator only uses loopback, not {host!r} ({url!r})")
        self.url = url
        self.world = world
        self.cfg = robot_cfg
        self.robot_id = robot_cfg.id
        self.system_id = robot_cfg.system_id
        self.profile = robot_cfg.profile
        self.gcs_id = robot_cfg.gcs_system_id
        self.clock = clock
        self.gcs_timeout = gcs_timeout
        self.target_timeout = target_timeout
        self.offboard_loss_timeout = offboard_loss_timeout
        self.fs_gcs_enable = fs_gcs_enable
        self.fs_action = fs_action
        self.unanswered = frozenset(unanswered)
        self.heartbeat_rate_fixed = heartbeat_rate_fixed
        self.max_rate_hz = max_rate_hz
        self.estimate_after = estimate_after
        self.arm_refusals = arm_refusals  # the first N arming requests fail (a pre-arm check)
        self.listener = listener
        self._world_lock = world_lock or threading.Lock()
        self._lock = threading.Lock()
        self.conn = _mavutil_v2().mavlink_connection(
            url, source_system=self.system_id, source_component=1
        )
        self.t_boot = clock()
        ardu = self.profile == "ardurover"
        self.autopilot = mc.AUTOPILOT_ARDUPILOT if ardu else mc.AUTOPILOT_PX4
        self.mode = mc.ROVER_MANUAL if ardu else mc.PX4_MANUAL
        self.armed = False
        self.silent = False
        self.closed = False
        self.intervals: dict[int, float | None] = {
            mc.MSG_HEARTBEAT: 1.0,
            mc.MSG_ATTITUDE: DEFAULT_INTERVAL,
            mc.MSG_LOCAL_POSITION_NED: DEFAULT_INTERVAL,
        }
        self._due: dict[int, float] = {}
        # ArduRover target: ("rate", speed, turn_rate_cw, t) or ("heading", speed, yaw_ned, t)
        self._target: tuple[str, float, float, float] | None = None
        # PX4 setpoint (FRD) and stream bookkeeping
        self._sp = (0.0, 0.0, 0.0)
        self._sp_last: float | None = None
        self._stream_start: float | None = None
        self._gcs_last: float | None = None
        self.failsafe = ""
        self.command = (0.0, 0.0, 0.0)  # FLU body command last given to the world
        self.setpoints: deque[SetpointRecord] = deque(maxlen=20000)
        self.counters = {
            "setpoints": 0,
            "ignored_setpoints": 0,
            "foreign": 0,  # messages addressed to another system
            "gcs_heartbeats": 0,
            "acks": 0,
            "param_reads": 0,
            "sent": 0,
        }
        self._thread: threading.Thread | None = None
        self._stop_evt = threading.Event()

    # ------------------------------------------------------------------ stepping

    def pump(self, now: float) -> None:
        """One non-blocking round at time ``now`` (s): inbound, failsafes, world command,
        telemetry."""
        with self._lock:
            if self.closed:
                return
            self._receive(now)
            self._update(now)
            if not self.silent:
                self._send_due(now)

    def set_silent(self, silent: bool) -> None:
        """Radio out: send nothing and drop everything received (failsafes still run)."""
        self.silent = silent

    def start(self) -> VehicleEmulator:
        """Run ``pump(clock())`` in a background thread until ``stop()``."""
        if self._thread is None:
            self._stop_evt.clear()
            self._thread = threading.Thread(
                target=self._run, name=f"mavlink-vehicle-{self.robot_id}", daemon=True
            )
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the background thread (if any) and close the socket. Idempotent."""
        self._stop_evt.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        with self._lock:
            if not self.closed:
                self.closed = True
                try:
                    self.conn.close()
                except OSError:
                    pass

    close = stop

    def _run(self) -> None:
        fd = self.conn.port.fileno()
        while not self._stop_evt.is_set():
            now = self.clock()
            try:
                self.pump(now)
            except Exception:  # noqa: BLE001 - keep the vehicle alive, say why
                log.exception("%s: emulator pump failed", self.robot_id)
            due = [d for d in self._due.values()]
            wait = min([d - self.clock() for d in due] + [0.02])
            try:
                select.select([fd], [], [], max(wait, 0.0005))
            except (OSError, ValueError):
                return

    # ------------------------------------------------------------------ inbound

    def _receive(self, now: float) -> None:
        for _ in range(4096):
            try:
                m = self.conn.recv_msg()
            except OSError:
                break
            if m is None:
                break
            if self.silent or m.get_type() == "BAD_DATA":
                continue
            self._handle(m, now)

    def _handle(self, m: Any, now: float) -> None:
        kind = m.get_type()
        if kind == "HEARTBEAT":
            if m.get_srcSystem() == self.gcs_id:
                self._gcs_last = now
                self.counters["gcs_heartbeats"] += 1
            return
        target = getattr(m, "target_system", None)
        if target is not None and target not in (0, self.system_id):
            self.counters["foreign"] += 1
            return
        if self.listener is not None:
            self.listener(m)
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            self._on_setpoint(m, now)
        elif kind == "COMMAND_LONG":
            result = self._on_command(m, now)
            self._ack(m, result)
        elif kind == "PARAM_REQUEST_READ":
            self._on_param_read(m)

    def _yaw_ned(self) -> float:
        with self._world_lock:
            pose = self.world.robot_pose(self.robot_id)
        return mc.enu_to_ned_pose(float(pose[0]), float(pose[1]), float(pose[2]))[2]

    def _body_velocity(self, frame: int, vx: float, vy: float) -> tuple[float, float] | None:
        """A setpoint's velocity as body FRD (forward, right) m/s, or None for other frames."""
        if frame in (mc.FRAME_BODY_NED, mc.FRAME_BODY_OFFSET_NED, mc.FRAME_BODY_FRD):
            return vx, vy
        if frame == mc.FRAME_LOCAL_NED:
            yaw = self._yaw_ned()
            c, s = math.cos(yaw), math.sin(yaw)
            return c * vx + s * vy, -s * vx + c * vy
        return None

    def _on_setpoint(self, m: Any, now: float) -> None:
        self.counters["setpoints"] += 1
        self.setpoints.append(
            SetpointRecord(
                now,
                m.target_system,
                m.coordinate_frame,
                m.type_mask,
                m.vx,
                m.vy,
                m.vz,
                m.yaw_rate,
            )  # fmt: skip
        )
        mask = m.type_mask
        vel_used = not (mask & mc.MASK_VEL)
        rate_used = not (mask & mc.MASK_YAW_RATE)
        plain = (mask & mc.MASK_POS) and (mask & mc.MASK_ACC) and (mask & mc.MASK_YAW)
        values = (m.vx, m.vy, m.yaw_rate)
        if not all(math.isfinite(v) for v in values):
            self.counters["ignored_setpoints"] += 1
            return
        if self.profile == "px4":
            if self._sp_last is None or now - self._sp_last > STREAM_GAP:
                self._stream_start = now
            self._sp_last = now
            body = self._body_velocity(m.coordinate_frame, m.vx, m.vy) if vel_used else None
            if not plain or body is None:
                self.counters["ignored_setpoints"] += 1
                self._sp = (0.0, 0.0, 0.0)
                return
            self._sp = (body[0], body[1], m.yaw_rate if rate_used else 0.0)
            return
        # ArduRover: only in GUIDED, only velocity (+ yaw rate) targets
        if self.mode != mc.ROVER_GUIDED or not plain or not vel_used:
            self.counters["ignored_setpoints"] += 1
            return
        if rate_used:
            body = self._body_velocity(m.coordinate_frame, m.vx, m.vy)
            if body is None:
                self.counters["ignored_setpoints"] += 1
                return
            # signed forward speed + turn rate: the lateral component is ignored
            self._target = ("rate", body[0], m.yaw_rate, now)
        else:
            speed = math.hypot(m.vx, m.vy)
            heading = math.atan2(m.vy, m.vx)
            if m.coordinate_frame != mc.FRAME_LOCAL_NED:
                heading += self._yaw_ned()
            self._target = ("heading", speed, wrap_angle(heading), now)

    def has_estimate(self, now: float) -> bool:
        """Whether the vehicle has its position estimate at ``now`` (``estimate_after``)."""
        return now - self.t_boot >= self.estimate_after

    def _statustext(self, severity: int, text: str) -> None:
        self._send(self.conn.mav.statustext_encode(severity, text.encode()[:50]))

    def _on_command(self, m: Any, now: float) -> int:
        cmd = m.command
        if cmd == mc.CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(m)
        if cmd == mc.CMD_COMPONENT_ARM_DISARM:
            if m.param1 > 0.5 and not self.armed and not self.has_estimate(now):
                self._statustext(3, "Arm: Need Position Estimate")
                return mc.RESULT_FAILED
            if m.param1 > 0.5 and not self.armed and self.arm_refusals > 0:
                self.arm_refusals -= 1
                self._statustext(3, "PreArm: Hardware safety switch")
                return mc.RESULT_FAILED
            self.armed = m.param1 > 0.5
            return mc.RESULT_ACCEPTED
        if cmd == mc.CMD_DO_SET_MODE:
            if not int(m.param1) & mc.MODE_FLAG_CUSTOM:
                return mc.RESULT_UNSUPPORTED
            wants = (int(m.param2) == mc.ROVER_GUIDED if self.profile == "ardurover"
                     else int(m.param2) == mc.PX4_MAIN_OFFBOARD)  # fmt: skip
            if wants and not self.has_estimate(now):
                self._statustext(4, "Flight mode change failed")
                return mc.RESULT_FAILED
            if self.profile == "ardurover":
                return self._set_rover_mode(int(m.param2))
            return self._set_px4_mode(int(m.param2), int(m.param3), now)
        return mc.RESULT_UNSUPPORTED

    def params(self) -> dict[str, float]:
        """The vehicle parameters it answers by name (its settings, as it behaves)."""
        if self.profile == "px4":
            table = {mc.PX4_OFFBOARD_LOSS_PARAM: float(self.offboard_loss_timeout)}
        else:
            table = {
                mc.ROVER_FS_GCS_ENABLE: 1.0 if self.fs_gcs_enable else 0.0,
                mc.ROVER_FS_TIMEOUT: float(self.gcs_timeout),
                mc.ROVER_FS_ACTION: float(self.fs_action),
                mc.ROVER_GUID_TIMEOUT: float(self.target_timeout),
            }
        return {k: v for k, v in table.items() if k not in self.unanswered}

    def _on_param_read(self, m: Any) -> None:
        self.counters["param_reads"] += 1
        name = m.param_id.decode() if isinstance(m.param_id, bytes) else str(m.param_id)
        name = name.rstrip("\x00")
        table = self.params()
        if name not in table:
            return
        index = sorted(table).index(name)
        self._send(
            self.conn.mav.param_value_encode(
                name.encode(), table[name], mc.PARAM_TYPE_REAL32, len(table), index
            )
        )

    def _set_interval(self, m: Any) -> int:
        msg_id = int(m.param1)
        if msg_id not in self.intervals:
            return mc.RESULT_UNSUPPORTED
        if msg_id == mc.MSG_HEARTBEAT and self.heartbeat_rate_fixed:
            return mc.RESULT_UNSUPPORTED
        if 0 < m.param2 < 1e6 / self.max_rate_hz - 1e-6:
            self._statustext(6, f"Requested rate for message ID {msg_id} too fast.")
            return mc.RESULT_DENIED
        if m.param2 < 0:
            self.intervals[msg_id] = None
        elif m.param2 == 0:
            self.intervals[msg_id] = 1.0 if msg_id == mc.MSG_HEARTBEAT else DEFAULT_INTERVAL
        else:
            self.intervals[msg_id] = m.param2 / 1e6
        self._due.pop(msg_id, None)
        return mc.RESULT_ACCEPTED

    def _set_rover_mode(self, mode: int) -> int:
        if mode not in mc.ROVER_MODES:
            return mc.RESULT_UNSUPPORTED
        if mode == mc.ROVER_GUIDED and self.mode != mc.ROVER_GUIDED:
            self._target = None  # GUIDED starts stopped
        self.mode = mode
        return mc.RESULT_ACCEPTED

    def _set_px4_mode(self, main: int, sub: int, now: float) -> int:
        if main == mc.PX4_MAIN_OFFBOARD:
            streaming = (
                self._sp_last is not None
                and self._stream_start is not None
                and now - self._sp_last <= STREAM_GAP
                and self._sp_last - self._stream_start >= STREAM_MIN - 1e-9
            )
            if not streaming:
                return mc.RESULT_TEMPORARILY_REJECTED
            self.mode = mc.PX4_OFFBOARD
            return mc.RESULT_ACCEPTED
        if main == mc.PX4_MAIN_MANUAL:
            self.mode = mc.PX4_MANUAL
            return mc.RESULT_ACCEPTED
        if main == mc.PX4_MAIN_AUTO and sub == mc.PX4_SUB_AUTO_LOITER:
            self.mode = mc.PX4_HOLD
            return mc.RESULT_ACCEPTED
        return mc.RESULT_UNSUPPORTED

    def _ack(self, m: Any, result: int) -> None:
        self.counters["acks"] += 1
        src_sys, src_comp = m.get_srcSystem(), m.get_srcComponent()
        self._send(self.conn.mav.command_ack_encode(m.command, result, 0, 0, src_sys, src_comp))

    # ------------------------------------------------------------------ state

    def _update(self, now: float) -> None:
        vx = vy = wz = 0.0  # FLU
        if self.profile == "ardurover":
            self._gcs_failsafe(now)
            tgt = self._target
            if self.armed and self.mode == mc.ROVER_GUIDED and tgt is not None:
                if now - tgt[3] > self.target_timeout:
                    self._target = None
                elif tgt[0] == "rate":
                    vx, wz = tgt[1], -tgt[2]
                else:
                    err = wrap_angle(tgt[2] - self._yaw_ned())
                    wz = -HEADING_GAIN * err  # NED error clockwise -> CCW rate
                    vx = tgt[1] * max(0.0, math.cos(err))
        else:
            if self.mode == mc.PX4_OFFBOARD and (
                self._sp_last is None or now - self._sp_last > self.offboard_loss_timeout
            ):
                log.warning("%s: offboard setpoints lost, HOLD", self.robot_id)
                self.mode = mc.PX4_HOLD
            if self.armed and self.mode == mc.PX4_OFFBOARD:
                vx, vy, wz = mc.frd_to_flu(*self._sp)
        vmax, wmax = self.cfg.max_speed, self.cfg.max_yaw_rate
        speed = math.hypot(vx, vy)
        if speed > vmax:
            vx, vy = vx * vmax / speed, vy * vmax / speed
        wz = max(-wmax, min(wmax, wz))
        self.command = (vx, vy, wz)
        with self._world_lock:
            self.world.set_command(self.robot_id, vx, vy, wz)

    def _gcs_failsafe(self, now: float) -> None:
        """ArduRover's GCS failsafe: ``gcs_timeout`` s without a GCS heartbeat (once one was
        seen) takes an armed rover, not in HOLD or RTL, to its ``fs_action``."""
        if not self.fs_gcs_enable:
            return
        if self._gcs_last is not None and now - self._gcs_last > self.gcs_timeout:
            quiet = (mc.ROVER_HOLD, mc.ROVER_RTL)
            if self.armed and self.mode not in quiet and not self.failsafe:
                mode = {mc.ROVER_FS_ACTION_HOLD: mc.ROVER_HOLD, 1: mc.ROVER_RTL, 3: mc.ROVER_RTL,
                        4: mc.ROVER_SMART_RTL}.get(self.fs_action)  # fmt: skip
                log.warning("%s: GCS failsafe, %s", self.robot_id, mc.mode_name("ardurover", mode)
                            if mode is not None else "no action")  # fmt: skip
                if mode is not None:
                    self.mode = mode
                self.failsafe = "gcs"
        elif self.failsafe == "gcs":
            self.failsafe = ""

    # ------------------------------------------------------------------ outbound

    def _send(self, msg: Any) -> None:
        if self.silent:
            return
        try:
            self.conn.mav.send(msg)
            self.counters["sent"] += 1
        except OSError:
            pass

    def _send_due(self, now: float) -> None:
        ms = int(max(0.0, now - self.t_boot) * 1000.0) & 0xFFFFFFFF
        sent_pose = False
        for msg_id in (mc.MSG_HEARTBEAT, mc.MSG_ATTITUDE, mc.MSG_LOCAL_POSITION_NED):
            interval = self.intervals[msg_id]
            if interval is None:
                self._due.pop(msg_id, None)
                continue
            due = self._due.get(msg_id, now)
            if now + 1e-9 < due:
                continue
            nxt = due + interval
            self._due[msg_id] = nxt if nxt > now else now + interval
            if msg_id == mc.MSG_HEARTBEAT:
                self._send_heartbeat()
                continue
            if not sent_pose:
                with self._world_lock:
                    pose = self.world.robot_pose(self.robot_id)
                    vel = self.world.robot_velocity(self.robot_id)
                n, e, yaw = mc.enu_to_ned_pose(float(pose[0]), float(pose[1]), float(pose[2]))
                vn, ve, yaw_rate = mc.enu_to_ned_velocity(
                    float(vel[0]), float(vel[1]), float(vel[2])
                )
                sent_pose = True
            if msg_id == mc.MSG_ATTITUDE:
                self._send(self.conn.mav.attitude_encode(ms, 0.0, 0.0, yaw, 0.0, 0.0, yaw_rate))
            elif self.has_estimate(now):
                self._send(self.conn.mav.local_position_ned_encode(ms, n, e, 0.0, vn, ve, 0.0))

    def _send_heartbeat(self) -> None:
        base = mc.MODE_FLAG_CUSTOM
        if self.armed:
            base |= mc.MODE_FLAG_ARMED
        if self.mode == (mc.ROVER_GUIDED if self.profile == "ardurover" else mc.PX4_OFFBOARD):
            base |= mc.MODE_FLAG_GUIDED
        status = 4 if self.armed else 3  # MAV_STATE_ACTIVE / STANDBY
        mode = self.mode
        self._send(
            self.conn.mav.heartbeat_encode(mc.TYPE_GROUND_ROVER, self.autopilot, base, mode, status)
        )


def start_emulators(
    world: World,
    robots: Iterable[RobotConfig],
    *,
    clock: Callable[[], float] = time.monotonic,
    threaded: bool = False,
    **kwargs: Any,
) -> list[VehicleEmulator]:
    """One emulator per robot with ``driver == "mavlink"``, answering its configured url.

    ``threaded`` starts each in its own thread; otherwise the caller pumps them."""
    out: list[VehicleEmulator] = []
    try:
        for r in robots:
            if r.driver != "mavlink":
                continue
            emu = VehicleEmulator(world, r, clock=clock, **kwargs)
            out.append(emu)
            if threaded:
                emu.start()
    except BaseException:
        for e in out:
            e.stop()
        raise
    return out
