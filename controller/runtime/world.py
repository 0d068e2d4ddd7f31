"""``fleet world``: the shared stand-in world as its own process, for a lab rehearsal.

One world (``sim.backend``: pybullet or ideal) with every ``sim`` robot of the config and the
object, paced on the wall clock (real time). On the bus it plays what a lab's hardware would:

- the motion-capture system: the object's measured pose on ``object/pose`` (the sensors' noise,
  dropouts and outliers at ``sim.object_pose_rate_hz``, stamped in the lab's clock domain: wall
  time, like the daemon's and the agents' stamps);
- every ``sim`` robot: it takes the command the robot's agent applies on
  ``sim/world/<id>/cmd`` (the agent's ``RemoteSimDriver``; the agent keeps its watchdog, e-stop
  and command gate) and puts the robot's measured pose back on ``sim/world/<id>/pose``; a robot
  whose command stream is silent for the command's ``ttl`` is stopped (the vehicle's own
  setpoint timeout);
- every MAVLink robot named in ``vehicles`` (``fleet world --mavlink``): a body of the same
  world behind an emulated flight controller (``sim_backend.mavlink_vehicle``) that answers the
  robot's ``url`` on loopback, as its vehicle would. The robot's agent (``fleet driver``) talks
  MAVLink to it with the real driver: the emulator takes SET_POSITION_TARGET_LOCAL_NED into the
  world body and reports LOCAL_POSITION_NED/ATTITUDE from the body's pose (NED), its failsafes
  (GUIDED target timeout, GCS failsafe, PX4 offboard loss) on the world's clock. It is pumped
  once per loop iteration at the wall clock's sim time: before the physics catches up (what
  arrived meanwhile is stamped when it arrived, so a world held up by the machine does not trip
  the vehicles' own timeouts) and after (telemetry). Nothing of it crosses the bus;
- every ROS 2 robot named in ``ros2`` (``fleet world --ros2``): a body of the same world behind
  the robot side of its ROS graph (``drivers.ros2.standin.RobotBase``: rmw_zenoh's keys,
  attachments and liveliness tokens, rosbags' CDR), on a zenoh session that answers the
  robot's ``ros2.connect`` endpoints on loopback as its router (rmw_zenohd) would: it listens
  there, or joins the router already there. The robot's agent (``fleet driver``) drives it with
  the real ROS 2 driver: the ``cmd_vel`` Twist/TwistStamped it takes is the body's command
  (dated when the loop takes it, at the wall clock's sim time, like the MAVLink setpoints; a
  ``cmd_vel`` silent for :data:`ROS2_CMD_TIMEOUT` stops the body, as a base's controller does),
  and it publishes the body's true pose at ``sim.pose_rate_hz`` (Odometry or PoseStamped, per
  ``ros2.pose_type``) in the robot's odom frame (``ros2.odom_to_world``), stamped with the
  world's sim time in the lab's clock domain (wall time, as the agents' ``time_source =
  "header"`` expects; the rmw attachment carries the same source time);
- ground truth on ``sim/truth/**`` at ``fleet.rate_hz`` (scoring and logs only), for the
  MAVLink and ROS 2 bodies too.

The world listens to nothing else: the object obeys its ``[object] motion`` and give-up rule
and physics decides contacts, whatever the controller says. Its session joins a ``fleet hub``
(or a listening daemon) on ``zenoh.listen``, or listens there itself when nobody does, so the
agents and a restarted daemon keep meeting through it. It declares ``alive/world/main``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import sys
import threading
import time
from collections.abc import Iterable

from controller import wire
from controller.config import ConfigError, FleetConfig
from controller.io.ratekeeper import Ratekeeper
from controller.runtime.daemon import open_daemon_bus
from controller.runtime.sole import already_served
from controller.runtime.wiring import make_hub, ros2_settings
from sim_backend.hub import SimHub

log = logging.getLogger(__name__)

ROS2_CMD_TIMEOUT = 0.5  # s: a ROS 2 body stops when cmd_vel is silent this long (a base's own
# timeout: ros2_control's diff_drive_controller cmd_vel_timeout defaults to 0.5 s)
LOOPBACK_HOSTS = ("127.0.0.1", "localhost")
MIN_LOOP_HZ = 50.0  # the world's I/O loop: commands in, samples out, at least this often
HELD_UP = 0.25  # s: a loop iteration later than this is reported (samples went out late)
RESUME_POLL = 0.25  # s between the latch queries of a world waiting for the operator's resume


class WorldServer:
    """The world's side of the bus: applied commands in, sensor samples and truth out.

    Time is passed in: ``time_offset`` (s) is added to sim time in every stamp (the wall-clock
    instant of sim time 0), ``mono`` (s, monotonic) times the vehicles' setpoint timeouts."""

    def __init__(
        self,
        bus,
        hub: SimHub,
        time_offset: float,
        sigma_xy: float,
        sigma_theta: float,
        vehicles: Iterable[str] = (),
    ):
        """``vehicles``: ids of the MAVLink and ROS 2 bodies of the world (truth only: their
        poses and commands go over MAVLink or the robot's ROS graph, not the fleet's keys)."""
        self.bus = bus
        self.hub = hub
        self.offset = time_offset
        self.sigma = (sigma_xy, sigma_theta)
        ids = tuple(hub.robot_sensors)
        self.robot_ids = ids
        self._cmds = bus.subscribe_topic("world_cmd")  # every robot's: the id is in the key
        self._poses = {rid: bus.publisher("world_pose", id=rid) for rid in ids}
        self._object = bus.publisher("object_pose")
        self.vehicle_ids = tuple(vehicles)
        self._truth_robot = {
            rid: bus.publisher("truth_robot", id=rid) for rid in ids + self.vehicle_ids
        }
        self._truth_object = bus.publisher("truth_object")
        self._expires: dict[str, float | None] = dict.fromkeys(ids)
        self._seq = dict.fromkeys(ids, 0)
        self._object_seq = 0
        self._truth_seq = 0
        self.commands = 0  # command samples received
        self.failsafe_stops = 0  # robots stopped by their setpoint timeout
        self.samples = 0  # pose samples published (robots and object)

    def commands_seen(self) -> int:
        """Command samples received so far, applied or still queued (a lockstep handshake)."""
        return self.commands + self._cmds.qsize()

    def published(self, robot_id: str) -> int:
        """Pose samples of ``robot_id`` published so far."""
        return self._seq[robot_id]

    def serving(self, robot_id: str) -> bool:
        """Whether some agent listens to ``robot_id``'s samples (the publisher matches)."""
        return self._poses[robot_id].matching()

    def apply_commands(self, mono: float) -> None:
        """Each robot's latest applied command; a silent stream past its ttl stops the robot."""
        latest: dict[str, wire.Twist2D] = {}
        for item in self._cmds.drain():
            parsed = wire.parse_key(item.key)
            if parsed is not None and parsed.id in self._expires:
                latest[parsed.id] = item.msg
                self.commands += 1
        w = self.hub.world
        for rid, cmd in latest.items():
            w.set_command(rid, cmd.vx, cmd.vy, cmd.wz)
            moving = cmd.vx != 0.0 or cmd.vy != 0.0 or cmd.wz != 0.0
            # a stopped robot has nothing to time out
            self._expires[rid] = (mono + cmd.ttl if cmd.ttl > 0 else math.inf) if moving else None
        for rid, due in self._expires.items():
            if rid not in latest and due is not None and mono > due:
                w.set_command(rid, 0.0, 0.0, 0.0)
                self._expires[rid] = None
                self.failsafe_stops += 1
                log.warning("robot %s: no command from its agent: stopped (setpoint timeout)", rid)

    def _pose(self, t: float, seq: int, x: float, y: float, th: float) -> wire.PoseMeasurement:
        return wire.PoseMeasurement(
            t=t + self.offset,
            seq=seq,
            x=x,
            y=y,
            theta=th,
            sigma_xy=self.sigma[0],
            sigma_theta=self.sigma[1],
            source="sim",
        )

    def publish_samples(self) -> int:
        """Every sensor sample taken since the last call; returns how many."""
        n = 0
        for rid, pub in self._poses.items():
            for t, x, y, th in self.hub.take_robot(rid):
                self._seq[rid] += 1
                pub.put(self._pose(t, self._seq[rid], x, y, th))
                n += 1
        for t, x, y, th in self.hub.take_object():
            self._object_seq += 1
            self._object.put(self._pose(t, self._object_seq, x, y, th))
            n += 1
        self.samples += n
        return n

    def publish_truth(self) -> None:
        """Ground truth of every robot and the object at the world's time."""
        w = self.hub.world
        self._truth_seq += 1
        t = self.hub.t + self.offset

        def truth(pose) -> wire.PoseMeasurement:
            x, y, th = (float(v) for v in pose)
            return wire.PoseMeasurement(
                t=t, seq=self._truth_seq, x=x, y=y, theta=th, sigma_xy=0.0, sigma_theta=0.0,
                source="truth",
            )  # fmt: skip

        for rid, pub in self._truth_robot.items():
            pub.put(truth(w.robot_pose(rid)))
        self._truth_object.put(truth(w.object_pose()))


def world_config(cfg: FleetConfig, vehicles: Iterable[str] = ()) -> FleetConfig:
    """The config of the shared world: its robots that are bodies of the world (``sim``), and
    the MAVLink and ROS 2 robots named in ``vehicles`` (emulated robots of this world; any other
    is a real robot, not a body of the stand-in world)."""
    keep = set(vehicles)
    return dataclasses.replace(
        cfg, robots=tuple(r for r in cfg.robots if r.spec.world_body or r.id in keep)
    )


def _chosen(cfg: FleetConfig, which: str | None, driver: str, flag: str, name: str) -> list:
    """The robots of ``driver`` a ``fleet world`` flag names: none (``which`` None), every one
    (``"all"``) or the comma-separated ids (ConfigError naming an id that is not one of them)."""
    if which is None:
        return []
    mine = [r for r in cfg.robots if r.driver == driver]
    if which.strip() == "all":
        return mine
    by_id = {r.id: r for r in mine}
    chosen = []
    for rid in (w.strip() for w in which.split(",") if w.strip()):
        if rid not in by_id:
            raise ConfigError(
                cfg.source,
                "robots",
                f"{flag} {rid!r}: not a {name} robot; {name} robots: {sorted(by_id)}",
            )
        chosen.append(by_id[rid])
    return chosen


def emulated_vehicles(cfg: FleetConfig, which: str | None) -> tuple[str, ...]:
    """The MAVLink robots ``fleet world --mavlink [IDS]`` makes bodies of the world: none
    (``which`` None), every one (``"all"``) or the comma-separated ids. ConfigError naming the
    id when it is not a MAVLink robot of the config, or when its url cannot be answered on
    loopback (``udpin`` on any host, ``udpout``/``tcp`` to 127.0.0.1)."""
    from sim_backend.mavlink_vehicle import vehicle_url

    chosen = _chosen(cfg, which, "mavlink", "--mavlink", "MAVLink")
    for r in chosen:
        try:
            vehicle_url(r.url)
        except ValueError as exc:
            i = cfg.robots.index(r)
            raise ConfigError(cfg.source, f"robots[{i}].url", f"--mavlink: {exc}") from None
    return tuple(r.id for r in chosen)


def ros2_bodies(cfg: FleetConfig, which: str | None) -> tuple[str, ...]:
    """The ROS 2 robots ``fleet world --ros2 [IDS]`` makes bodies of the world: none (``which``
    None), every one (``"all"``) or the comma-separated ids. ConfigError naming the id when it
    is not a ROS 2 robot of the config, or naming ``robots[i].ros2.connect`` when an endpoint
    of its router is not on loopback (the world answers it there)."""
    chosen = _chosen(cfg, which, "ros2", "--ros2", "ROS 2")
    for r in chosen:
        for endpoint in r.ros2.connect:
            host = endpoint.partition("/")[2].rpartition(":")[0]
            if host not in LOOPBACK_HOSTS:
                i = cfg.robots.index(r)
                raise ConfigError(
                    cfg.source,
                    f"robots[{i}].ros2.connect",
                    f"--ros2: the world answers a robot's router only on loopback, not "
                    f"{endpoint!r}",
                )
    return tuple(r.id for r in chosen)


class Ros2Bodies:
    """ROS 2 robots as bodies of the world: the robot side of each one's ROS graph
    (``drivers.ros2.standin.RobotBase``, rosbags' CDR) on one zenoh session per distinct set
    of ``ros2.connect`` endpoints, which listens there as the robot's router would (or, when
    something already listens there, e.g. rmw_zenohd or the fleet's own endpoint, joins it as
    a client). Driven by the world's loop: :meth:`apply` before the physics, :meth:`publish`
    after."""

    def __init__(self, cfg: FleetConfig, hub: SimHub, ids: Iterable[str], time_offset: float):
        from drivers.ros2.node import open_session
        from drivers.ros2.standin import RobotBase

        self.hub = hub
        self.offset = time_offset
        self.period = 1.0 / cfg.sim.pose_rate_hz
        self.sessions: dict[tuple[str, ...], object] = {}
        self.how: dict[str, str] = {}  # robot id -> "listens on ..." / "joined ..."
        self.robots: dict[str, RobotBase] = {}
        self._last_cmd: dict[str, float | None] = {}
        self._next_pose = hub.t
        self.timeout_stops = 0
        try:
            for rid in ids:
                r = cfg.robot(rid)
                s = ros2_settings(r)
                ends = tuple(s.connect)
                if ends not in self.sessions:
                    self.sessions[ends], how = _ros2_session(open_session, ends)
                    self.how.update({e: how for e in ends})
                self.robots[rid] = RobotBase(self.sessions[ends], s, r.kind == "omni")
                self._last_cmd[rid] = None
        except BaseException:
            self.close()
            raise

    def commands(self) -> int:
        """``cmd_vel`` samples taken so far."""
        return sum(b.received for b in self.robots.values())

    def apply(self, t: float) -> None:
        """Each body's latest ``cmd_vel`` to the world, dated ``t`` (s, sim time: the wall
        clock's, so a world held up by the machine does not time out what kept arriving); a
        body whose ``cmd_vel`` is silent past :data:`ROS2_CMD_TIMEOUT` is stopped."""
        w = self.hub.world
        for rid, base in self.robots.items():
            cmd = base.take_command()
            if cmd is not None:
                w.set_command(rid, *cmd)
                moving = any(v != 0.0 for v in cmd)
                self._last_cmd[rid] = t if moving else None  # a stopped body has no timeout
                continue
            last = self._last_cmd[rid]
            if last is not None and t - last > ROS2_CMD_TIMEOUT:
                w.set_command(rid, 0.0, 0.0, 0.0)
                self._last_cmd[rid] = None
                self.timeout_stops += 1
                log.warning("ROS 2 robot %s: cmd_vel silent %.2f s: stopped", rid, t - last)

    def publish(self) -> None:
        """Every body's true pose (odom frame) when one is due at the world's time, stamped
        with it in the lab's clock domain; the Odometry's twist is the body's (body frame)."""
        t = self.hub.t
        if not self.robots or t + 1e-9 < self._next_pose:
            return
        self._next_pose = max(self._next_pose + self.period, t)
        w = self.hub.world
        for rid, base in self.robots.items():
            x, y, th = (float(v) for v in w.robot_pose(rid))
            vx, vy, wz = (float(v) for v in w.robot_velocity(rid))
            c, s = math.cos(th), math.sin(th)
            base.publish_pose(t + self.offset, x, y, th, (c * vx + s * vy, -s * vx + c * vy, wz))

    def close(self) -> None:
        """Undeclare every robot's node and close the sessions (the counters stay)."""
        for base in self.robots.values():
            base.close()
        for session in self.sessions.values():
            session.close()
        self.sessions = {}


def _ros2_session(open_session, endpoints: tuple[str, ...]):
    """A session answering ``endpoints`` as the robots' router: listening there (peer), or,
    when something already listens, joined to it (client). Returns (session, how)."""
    try:
        return open_session(listen=list(endpoints), mode="peer"), "listening"
    except Exception:  # noqa: BLE001 - zenoh.ZError: the address is taken (a router is there)
        return open_session(connect=list(endpoints), mode="client"), "joined"


class ResumeWatch:
    """The operator's first resume, as the world sees it (``sim.object_start = "resume"``): a
    thread asks every latch holder every :data:`RESUME_POLL` s until a hub or a controller
    answers *released* (a robot's answer never counts: a robot may stop the fleet, never
    release it), then sets :attr:`released` and ends."""

    def __init__(self, bus, stop: threading.Event) -> None:
        self.bus = bus
        self.stop = stop
        self.released = threading.Event()
        self.thread = threading.Thread(target=self._run, name="resume-watch", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        from controller.latch import TRUSTED_ROLES, role_of

        key = self.bus.estop_wildcard()
        while not self.stop.is_set():
            try:
                replies = list(self.bus.query_replies(key, wire.EStop, RESUME_POLL))
            except Exception:  # noqa: BLE001 - the session closing under us: stop asking
                return
            for k, msg in replies:
                if role_of(k, self.bus.fleet) in TRUSTED_ROLES and not msg.engaged:
                    self.released.set()
                    return
            self.stop.wait(RESUME_POLL)


def run_world(
    cfg: FleetConfig,
    stop: threading.Event,
    duration: float = 0.0,
    mavlink: str | None = None,
    ros2: str | None = None,
) -> int:
    """Serve the world until ``stop`` (or ``duration`` s of wall time). Exit 0; 1 when another
    world already serves the fleet.

    ``mavlink``: which MAVLink robots are emulated vehicles of this world, ``ros2``: which ROS
    2 robots are bodies of it (``"all"`` or ids separated by commas; None: none)."""
    vehicles = emulated_vehicles(cfg, mavlink)
    ros2_ids = ros2_bodies(cfg, ros2)
    hub = make_hub(world_config(cfg, vehicles + ros2_ids))
    emulators = _start_vehicles(cfg, hub, vehicles)
    bodies = None
    try:
        bus, how = open_daemon_bus(cfg)
        with bus:
            if already_served(bus, "world", "main", cfg.fleet.liveliness_lease, stop):
                print(
                    f"fleet world: another world already serves fleet {cfg.fleet.name!r} (its "
                    "liveliness token alive/world/main stayed on the bus past its lease): two "
                    "worlds would each move their own copy of the robots; stop the other one",
                    file=sys.stderr,
                    flush=True,
                )
                return 1
            bus.declare_alive("world", "main")
            mono0, wall0 = time.monotonic(), time.time()
            noise = cfg.sim.pose_noise
            server = WorldServer(
                bus, hub, wall0 - hub.t, noise.xy, noise.theta, vehicles + ros2_ids
            )
            bodies = Ros2Bodies(cfg, hub, ros2_ids, wall0 - hub.t)
            resume = None
            if cfg.sim.object_start == "resume":
                hub.world.hold_object()
                resume = ResumeWatch(bus, stop)
            urls = {e.robot_id: e.url for e in emulators}
            ros = {rid: list(b.settings.connect) for rid, b in bodies.robots.items()}
            print(
                f"fleet world: fleet {cfg.fleet.name!r}, {cfg.sim.backend} backend, robots "
                f"{list(server.robot_ids)}, MAVLink vehicles {urls}, ROS 2 robots {ros} "
                f"({bodies.how}), on {list(cfg.zenoh.listen)} ({how})",
                file=sys.stderr,
                flush=True,
            )
            if resume is not None:
                print(
                    "fleet world: the object holds its start pose until an operator's first "
                    'resume (sim.object_start = "resume")',
                    file=sys.stderr,
                    flush=True,
                )
            stats = _serve(cfg, server, stop, duration, mono0, emulators, bodies, resume)
    finally:
        for e in emulators:
            e.stop()
        if bodies is not None:
            bodies.close()
        hub.world.close()
    _report(hub, server, stats, emulators, bodies)
    return 0


def _report(hub: SimHub, server: WorldServer, stats, emulators, bodies: Ros2Bodies) -> None:
    """The world's last line on stderr: time served, load, what went through it."""
    wall, busy = stats
    rtf, load = hub.t / max(wall, 1e-9), busy / max(wall, 1e-9)
    setpoints = sum(e.counters["setpoints"] for e in emulators)
    print(
        f"fleet world: stopped at sim time {hub.t:.2f} s after {wall:.2f} s of wall time "
        f"(real-time factor {rtf:.3f}; stepping took {load:.1%} of the wall time); "
        f"{server.commands} commands, {server.samples} samples, "
        f"{server.failsafe_stops} setpoint-timeout stops; {len(emulators)} MAVLink vehicles, "
        f"{setpoints} setpoints; {len(bodies.robots)} ROS 2 robots, "
        f"{bodies.commands()} cmd_vel, {bodies.timeout_stops} cmd_vel-timeout stops",
        file=sys.stderr,
    )


def _start_vehicles(cfg: FleetConfig, hub: SimHub, vehicles: tuple[str, ...]) -> list:
    """One emulated flight controller per id in ``vehicles``, on the world's (sim) clock; the
    caller pumps them (``pump_vehicles``)."""
    if not vehicles:
        return []
    from sim_backend.mavlink_vehicle import start_emulators

    robots = [r for r in cfg.robots if r.id in vehicles]
    return start_emulators(hub.world, robots, clock=lambda: hub.t)


def pump_vehicles(emulators, t: float) -> None:
    """One round of every emulated vehicle at sim time ``t`` (s): MAVLink in, its failsafes and
    command to the world, telemetry due out."""
    for e in emulators:
        e.pump(t)


def _serve(
    cfg: FleetConfig,
    server: WorldServer,
    stop: threading.Event,
    duration: float,
    mono0: float,
    emulators=(),
    bodies: Ros2Bodies | None = None,
    resume: ResumeWatch | None = None,
) -> tuple[float, float]:
    """The real-time loop. Returns (wall seconds served, seconds spent stepping physics)."""
    hub = server.hub
    t_start = hub.t
    rk = Ratekeeper(max(MIN_LOOP_HZ, cfg.sim.pose_rate_hz, cfg.sim.object_pose_rate_hz))
    truth_period = 1.0 / cfg.fleet.rate_hz
    next_truth = 0.0
    busy = 0.0
    last = time.monotonic()
    while not stop.is_set():
        rk.keep_time()
        mono = time.monotonic()
        if mono - last > HELD_UP:
            log.warning(
                "the world's loop was held up %.2f s (the machine is overloaded?)", mono - last
            )
        last = mono
        server.apply_commands(mono)
        if resume is not None and resume.released.is_set():
            hub.world.start_object()
            resume = None
            log.info("the object's path begins at sim time %.2f s (the operator's resume)", hub.t)
        target = t_start + mono - mono0
        pump_vehicles(emulators, target)  # MAVLink in, stamped at the wall clock's sim time
        if bodies is not None:
            bodies.apply(target)  # cmd_vel in, likewise
        b0 = time.perf_counter()
        hub.advance_to(target)
        busy += time.perf_counter() - b0
        pump_vehicles(emulators, hub.t)  # telemetry of the new state
        if bodies is not None:
            bodies.publish()  # odometry of the new state
        server.publish_samples()
        if mono - mono0 >= next_truth:
            server.publish_truth()
            next_truth += truth_period
        if duration and mono - mono0 >= duration:
            break
    return time.monotonic() - mono0, busy
