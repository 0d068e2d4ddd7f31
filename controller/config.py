"""fleet.toml: load once, validate strictly, return frozen dataclasses.

Every section is a frozen dataclass whose fields carry their own rules in ``metadata``
(``min``, ``max``, ``gt`` for a strict lower bound, ``choices``). The loader walks the TOML tables
against those dataclasses, so an unknown key, a wrong type or an out-of-range value is reported
with the file, the full key path, what was expected and, for unknown keys, a did-you-mean.
Cross-field rules (polygons, unique ids, robot starts) run after the walk.

Units are SI unless the key's name says otherwise (``_deg``, ``_hz``).
"""

from __future__ import annotations

import dataclasses
import difflib
import ipaddress
import json
import math
import os
import re
import tempfile
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller import geometry

# Registries by name. Kept here (not in drivers/) so config validation needs no driver import.
ROBOT_KINDS = ("omni", "diff")
DRIVERS = ("sim", "mavlink")
MAVLINK_PROFILES = ("ardurover", "px4")
MOTION_KINDS = ("line", "sine", "evade", "static", "inert")  # inert: no drive, limp from t = 0
CLOSURE_MODES = ("exact", "paper")
CAPTURE_GAS = ("ours", "paper")  # capture.ga: our GA + local search, or Sharma's as published
HEURISTICS = ("euclid", "wavefront", "skeleton", "cost_to_go")
#: Grid budgets: object route states (cells x heading bins) and robot route cells. Above them a
#: plan takes minutes and gigabytes (512 x 512 x 36 states take about 5 s and 0.6 GB).
ROUTE_MAX_STATES = 10_000_000
ROBOT_ROUTE_MAX_CELLS = 512 * 512
TRANSPORT_STRATEGIES = ("sa", "serpentine", "downhill")
TRANSPORT_SCHEDULES = ("geometric", "logarithmic")
TRANSPORT_INITIAL = ("lp", "hold", "random")
SIM_BACKENDS = ("pybullet", "ideal")
# where a `fleet driver` of a `sim` robot finds its world: "solo" (a world of its own, that robot
# alone) or "process" (the shared `fleet world` process, over the bus)
SIM_WORLDS = ("solo", "process")
FILTERS = ("ekf", "ukf")
ZENOH_MODES = ("peer", "client", "router")
# access-control profiles generated from the config (controller/acl.py); else zenoh.acl is a file
ACL_PROFILES = ("lab",)
# zenoh locators: ``proto/host:port`` (checked: host and port) for these, ``proto/address`` for
# the others zenoh knows
ZENOH_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic")
ZENOH_OTHER_PROTOCOLS = ("ws", "unixsock-stream", "unixpipe", "serial", "vsock")
# what fleet daemon --mission and build_mission run ("transport": carry an object the robots
# already hold, from where they stand; "capture": the whole job)
MISSION_KINDS = ("capture", "transport", "stage", "hold")
# The capture planner's node budget: candidate nodes on the object's boundary at capture.spacing
# (its per-problem tables grow linearly with the count, the GA's work per generation too).
CAPTURE_NODE_BUDGET = 20_000

Point = tuple[float, float]
Pose = tuple[float, float, float]
Polygon = tuple[Point, ...]


class ConfigError(ValueError):
    """A config that does not validate; ``path`` is the dotted key path of the culprit."""

    def __init__(self, source: str, path: str, message: str):
        self.source = source
        self.path = path
        self.message = message
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{path or '<root>'}: {message}")


class InputError(ValueError):
    """Bad input other than the config: a missing or unreadable file, an option out of range
    (the CLI exits 2 with the message)."""


def _rule(default: Any = dataclasses.MISSING, **meta: Any) -> Any:
    if default is dataclasses.MISSING:
        return field(metadata=meta)
    if isinstance(default, list | dict):
        raise TypeError("use tuples for defaults")
    return field(default=default, metadata=meta)


# --------------------------------------------------------------------------- sections


@dataclass(frozen=True, kw_only=True)
class FleetSection:
    name: str = _rule(pattern=r"^[A-Za-z0-9_\-]+$")
    rate_hz: float = _rule(20.0, gt=0, max=1000)
    cmd_ttl: float = _rule(0.3, gt=0, max=10)
    stale_after: float = _rule(0.3, gt=0, max=10)
    liveliness_lease: float = _rule(1.0, gt=0, max=60)
    # s after the first estimates: the capture starts without robots never seen by then (once
    # the object and enough robots to close it are seen); a robot seen later joins as a spare
    start_wait: float = _rule(5.0, min=0, max=3600)
    # s: a pose or command stamped further than this from the receiver's clock (same domain:
    # wall time in the lab, sim time in the dry run) is dropped and counted
    max_clock_skew: float = _rule(1.0, gt=0, max=3600)


@dataclass(frozen=True, kw_only=True)
class TlsSection:
    """``[zenoh] tls``: PEM files. The listening hub presents ``certificate``/``private_key`` and
    checks peers against ``root_ca``; the others check the hub against ``root_ca`` and, with
    ``mtls``, present ``certificate``/``private_key`` themselves (a robot may have its own:
    ``robots[i].zenoh_certificate``)."""

    certificate: str = _rule("")
    private_key: str = _rule("")
    root_ca: str = _rule("")
    mtls: bool = _rule(False)


@dataclass(frozen=True, kw_only=True)
class ZenohSection:
    mode: str = _rule("peer", choices=ZENOH_MODES)
    listen: tuple[str, ...] = _rule(("tcp/127.0.0.1:7447",))
    connect: tuple[str, ...] = _rule(())
    multicast_scouting: bool = _rule(False)
    gossip_scouting: bool = _rule(False)
    # Security (README "In the lab: secure profile"). Files are checked when a session that
    # needs them is built (a robot's computer holds only its own), relative to the config file.
    config_file: str = _rule("")  # a zenoh JSON5 config, our settings applied over it
    user: str = _rule("")  # this process's identity (controller, recorder, CLI by default)
    password: str = _rule("")
    password_file: str = _rule("")
    auth_dictionary: str = _rule("")  # the listening hub's usrpwd dictionary (user:password)
    tls: TlsSection | None = _rule(None)
    acl: str = _rule("")  # a JSON5 access_control block file, or a profile (ACL_PROFILES)
    operators: tuple[str, ...] = _rule(())  # usernames that may put estop/resume (acl profile)
    # filled by the loader for an acl profile: the generated access_control block (JSON)
    acl_block: str = _rule("", internal=True)

    @property
    def secured(self) -> bool:
        """Whether a listening hub refuses strangers (a password dictionary or mutual TLS)."""
        return bool(self.auth_dictionary) or bool(self.tls and self.tls.mtls)


@dataclass(frozen=True)
class ZenohIdentity:
    """Who a session authenticates as: a usrpwd user and its password (given or in a file), and
    for mutual TLS its own certificate. ``path`` is the config key path it came from."""

    path: str = "zenoh"
    user: str = ""
    password: str = ""
    password_file: str = ""
    certificate: str = ""
    private_key: str = ""


@dataclass(frozen=True, kw_only=True)
class LogSection:
    dir: str = _rule("runs")
    flush_interval: float = _rule(0.5, gt=0, max=10)
    scene_hz: float = _rule(10.0, min=0, max=100)  # Foxglove scene channels per second (0: none)
    split_s: float = _rule(0.0, min=0, max=86400)  # a new indexed segment every S s (0: one file)


@dataclass(frozen=True, kw_only=True)
class VizSection:
    """The live view (``fleet run --viz``, ``fleet daemon --viz``): a Foxglove WebSocket server
    on 127.0.0.1 (``port`` 0: any free port), with a bounded queue of ``queue`` messages."""

    port: int = _rule(8765, min=0, max=65535)
    queue: int = _rule(4096, min=16, max=1_000_000)


@dataclass(frozen=True, kw_only=True)
class WorldSection:
    bounds: tuple[Point, Point] = _rule(((0.0, 0.0), (12.8, 12.8)))
    walls: bool = _rule(True)


@dataclass(frozen=True, kw_only=True)
class Obstacle:
    polygon: Polygon = _rule()
    height: float = _rule(0.3, gt=0, max=10)


@dataclass(frozen=True, kw_only=True)
class MotionSection:
    kind: str = _rule("sine", choices=MOTION_KINDS)
    speed: float = _rule(0.1, min=0, max=10)
    amplitude: float = _rule(0.5, min=0, max=100)
    wavelength: float = _rule(4.0, gt=0, max=1000)
    heading: float = _rule(0.0, min=-10, max=10)
    max_speed: float = _rule(0.2, min=0, max=10)
    flee_radius: float = _rule(1.5, gt=0, max=100)
    max_force: float = _rule(4.0, gt=0, max=1e4)
    # s the live object keeps fighting while it cannot follow its script (held by robots, pinned
    # against a wall) before it gives up and goes limp ("compromised"); 0: it never gives up
    give_up_after: float = _rule(6.0, min=0, max=1e5)


@dataclass(frozen=True, kw_only=True)
class ObjectSection:
    polygon: Polygon = _rule()
    mass: float = _rule(4.0, gt=0, max=1e4)
    floor_friction: float = _rule(0.2, min=0, max=2)
    contact_friction: float = _rule(0.0, min=0, max=2)
    height: float = _rule(0.2, gt=0, max=10)
    start: Pose = _rule()
    # where the robots carry the object after the arrest; without it the job is the capture
    goal: Pose | None = _rule(None)
    motion: MotionSection = _rule(MotionSection())


@dataclass(frozen=True, kw_only=True)
class CaptureSection:
    spacing: float = _rule(0.1, gt=0, max=10)
    clearance: float = _rule(0.02, min=0, max=1)
    k: float = _rule(1.0, min=0, max=10)
    epsilon: float = _rule(0.1, gt=0, max=100)
    tau: float = _rule(1e-9, min=0, max=1)
    population: int = _rule(60, min=2, max=100000)
    crossover: float = _rule(0.8, min=0, max=1)
    mutation: float = _rule(0.12, min=0, max=1)
    generations: int = _rule(600, min=1, max=1000000)
    seed: int = _rule(0, min=0)
    closure: str = _rule("exact", choices=CLOSURE_MODES)
    ga: str = _rule("ours", choices=CAPTURE_GAS)
    # N: the largest push of the object the robots must resist at their contacts (and that force
    # times its radius of gyration in torque), with every robot at most its max_force; points
    # are added to the GA's set until it holds; 0: no check
    hold_force: float = _rule(4.0, min=0, max=1e4)


@dataclass(frozen=True, kw_only=True)
class ApproachSection:
    max_turn_deg: float = _rule(15.0, gt=0, max=180)
    projection: float = _rule(2.5, gt=0, max=10)
    alpha_deg: float = _rule(15.0, gt=0, max=180)
    alpha_growth: float = _rule(1.25, gt=1, max=10)
    alpha_max_deg: float = _rule(180.0, gt=0, max=180)
    envelope_margin: float = _rule(0.25, min=0, max=10)
    # m: a robot is in contact when its disc's estimated gap to the object is below this
    contact_tolerance: float = _rule(0.015, gt=0, max=1)
    envelope_tolerance: float = _rule(0.08, gt=0, max=1)
    hold_s: float = _rule(2.0, min=0, max=600)  # s of held contact before the arrest
    # m: the object (any vertex of its estimate) may move this much during the hold
    hold_tolerance: float = _rule(0.03, gt=0, max=10)
    # m: how far into the object's estimate a robot in contact aims (its preload; the physics
    # stops it at the surface, so it pushes with up to its max_force)
    preload_depth: float = _rule(0.0, min=0, max=0.2)
    # s: the longest look-ahead when aiming at where a moving object will be (interception)
    intercept_horizon: float = _rule(8.0, min=0, max=600)
    prediction_horizon: float = _rule(0.5, min=0, max=10)
    safety_margin: float = _rule(0.05, min=0, max=1)
    max_accel: float = _rule(1.0, gt=0, max=100)
    timeout: float = _rule(180.0, gt=0, max=1e5)


@dataclass(frozen=True, kw_only=True)
class RouteSection:
    resolution: float = _rule(0.1, gt=0, max=10)
    heading_bins: int = _rule(36, min=1, max=3600)
    heuristic: str = _rule("cost_to_go", choices=HEURISTICS)
    wg: float = _rule(1.0, choices=(0.0, 1.0))
    wh: float = _rule(1.0, min=0, max=100)
    reopen: bool = _rule(False)  # re-open closed states when wh > 1 (A* always, greedy never)
    robot_resolution: float = _rule(0.1, gt=0, max=10)  # m: the robots' own 2-D routes
    speed: float = _rule(0.2, gt=0, max=10)
    yaw_rate: float = _rule(0.3, gt=0, max=100)
    manipulation_cost: float = _rule(2.0, min=0, max=1e4)
    subgoal_spacing: float = _rule(1.0, gt=0, max=100)


@dataclass(frozen=True, kw_only=True)
class TransportSection:
    """Carrying the arrested object (controller/planning/transport*.py). Weights k_* are the
    energy's K constants (Vass Eq. 3 plus route deviation and progress), per unit named."""

    strategy: str = _rule("sa", choices=TRANSPORT_STRATEGIES)
    tolerance: float = _rule(0.2, gt=0, max=10)
    heading_tolerance_deg: float = _rule(10.0, gt=0, max=180)
    stall_timeout: float = _rule(10.0, gt=0, max=1e5)
    # s the fleet keeps holding the arrested object before carrying it: a live object fights
    # a hold for object.motion.give_up_after s, then goes limp (the paper's "compromised")
    start_after: float = _rule(5.0, min=0, max=1e4)
    intervals: int = _rule(8, min=1, max=1000)
    interval: float = _rule(0.5, gt=0, max=60)  # s, shortest interval (else t_subgoal / n)
    iterations: int = _rule(100, min=1, max=10**7)  # per plan (each control interval)
    initial_temperature: float = _rule(0.3, gt=0, max=1e6)
    cooling: float = _rule(0.95, gt=0, max=1)  # per iteration (geometric schedule)
    schedule: str = _rule("geometric", choices=TRANSPORT_SCHEDULES)
    initial_actions: str = _rule("lp", choices=TRANSPORT_INITIAL)
    block_moves: float = _rule(0.5, min=0, max=1)  # share of proposals V[j:, i] = x
    seed: int = _rule(0, min=0)
    speed: float = _rule(0.15, gt=0, max=10)  # m/s, object (centroid + mean radius x yaw rate)
    lookahead: float = _rule(0.3, gt=0, max=100)  # m along the route
    slide_speed: float = _rule(0.2, gt=0, max=10)  # m/s along the boundary
    push_bias: float = _rule(0.02, min=0, max=1)  # m/s into the object for pushers
    relocation_spacing: float = _rule(0.1, gt=0, max=10)  # m between scanned nodes
    k_collision: float = _rule(100.0, min=0, max=1e9)  # per interval with a collision
    k_equilibrium: float = _rule(100.0, min=0, max=1e9)  # per interval whose LP is infeasible
    k_force: float = _rule(0.01, min=0, max=1e9)  # per N of contact force per interval
    k_change: float = _rule(0.05, min=0, max=1e9)  # per change of a robot's action
    k_deviation: float = _rule(1.0, min=0, max=1e9)  # per m of deviation per interval
    k_progress: float = _rule(10.0, min=0, max=1e9)  # per m of progress along the route
    serpentine_deviation: float = _rule(0.15, gt=0, max=100)  # m, switch threshold at start
    serpentine_min_deviation: float = _rule(0.03, gt=0, max=100)  # m, near the goal


@dataclass(frozen=True, kw_only=True)
class EstimationSection:
    filter: str = _rule("ekf", choices=FILTERS)
    gate_probability: float = _rule(0.999, gt=0, max=1)
    process_accel: float = _rule(0.3, gt=0, max=1e3)
    process_yaw_accel: float = _rule(1.0, gt=0, max=1e3)
    object_process_accel: float = _rule(0.1, gt=0, max=1e3)
    meas_xy: float = _rule(0.01, gt=0, max=10)
    meas_theta: float = _rule(0.0175, gt=0, max=10)
    command_tau: float = _rule(0.15, gt=0, max=10)
    reacquire_after: int = _rule(5, min=1, max=100000)
    object_arrested_accel: float = _rule(0.05, gt=0, max=1e3)
    init_sigma_speed: float = _rule(0.5, gt=0, max=100)
    init_sigma_yaw_rate: float = _rule(1.0, gt=0, max=100)


@dataclass(frozen=True, kw_only=True)
class PoseNoise:
    xy: float = _rule(0.01, min=0, max=10)
    theta: float = _rule(0.0175, min=0, max=10)


@dataclass(frozen=True, kw_only=True)
class SimSection:
    backend: str = _rule("pybullet", choices=SIM_BACKENDS)
    world: str = _rule("solo", choices=SIM_WORLDS)  # what `fleet driver` attaches a sim robot to
    timestep: float = _rule(1.0 / 240.0, gt=0, max=1)
    seed: int = _rule(0, min=0)
    pose_noise: PoseNoise = _rule(PoseNoise())
    pose_rate_hz: float = _rule(30.0, gt=0, max=1000)
    object_pose_rate_hz: float = _rule(30.0, gt=0, max=1000)
    dropout: float = _rule(0.0, min=0, max=1)
    outlier_rate: float = _rule(0.0, min=0, max=1)
    outlier_magnitude: float = _rule(0.5, min=0, max=100)
    realtime: bool = _rule(False)
    tick_timeout: float = _rule(2.0, gt=0, max=600)
    max_time: float = _rule(300.0, gt=0, max=1e6)
    # the pybullet object as it really is, against what [object] tells the controller (the
    # robustness sweep of bench/transport.py; 1, 1 and (0, 0): the same object)
    object_mass_scale: float = _rule(1.0, gt=0, max=100)
    object_friction_scale: float = _rule(1.0, min=0, max=100)
    object_com_offset: Point = _rule((0.0, 0.0))
    # robot motion errors (Yamashita et al. Table 1: ±0.04 m, ±0.01 m): each robot's pose
    # reports are off its true pose by a fixed offset drawn U(−x, x), U(−y, y) per run, world
    # frame (m); the controller steers the robot that far off where it means it to be
    robot_position_error: Point = _rule((0.0, 0.0))


@dataclass(frozen=True, kw_only=True)
class RobotConfig:
    id: str = _rule(pattern=r"^[A-Za-z0-9_\-]+$")
    kind: str = _rule(choices=ROBOT_KINDS)
    radius: float = _rule(0.1, gt=0, max=5)
    max_speed: float = _rule(0.5, gt=0, max=20)
    max_yaw_rate: float = _rule(2.0, gt=0, max=50)
    max_accel: float = _rule(1.0, gt=0, max=100)
    max_force: float = _rule(20.0, gt=0, max=1e4)
    mass: float = _rule(2.0, gt=0, max=1e4)
    driver: str = _rule("sim", choices=DRIVERS)
    start: Pose = _rule()
    url: str = _rule("")
    system_id: int = _rule(1, min=1, max=255)
    profile: str = _rule("", choices=("",) + MAVLINK_PROFILES)
    # s without a vehicle HEARTBEAT before the link is lost; 2.5 periods of a vehicle's default
    # 1 Hz heartbeat (the driver widens it to 2.5 periods of what the vehicle really sends)
    link_timeout: float = _rule(2.5, gt=0, max=60)
    arm: bool = _rule(True)
    hold_on_close: bool = _rule(True)  # the driver switches the vehicle to HOLD when it closes
    # s: the longest the vehicle may keep its last setpoint once our stream stops (PX4
    # COM_OF_LOSS_T, read on connect: a warning above it, `fleet driver --strict` refuses)
    max_vehicle_timeout: float = _rule(1.0, gt=0, max=60)
    gcs_system_id: int = _rule(255, min=1, max=255)  # our MAVLink system id (the GCS failsafe's)
    telemetry_hz: float = _rule(50.0, min=30, max=1000)  # LOCAL_POSITION_NED/ATTITUDE rate asked
    # the robot agent's own zenoh identity (else the [zenoh] one): the lab ACL profile lets it
    # put only this robot's pose/event and receive only this robot's commands
    zenoh_user: str = _rule("")
    zenoh_password: str = _rule("")
    zenoh_password_file: str = _rule("")
    zenoh_certificate: str = _rule("")  # mutual TLS: this robot's own certificate and key
    zenoh_private_key: str = _rule("")


@dataclass(frozen=True, kw_only=True)
class FleetConfig:
    fleet: FleetSection
    object: ObjectSection
    robots: tuple[RobotConfig, ...]
    zenoh: ZenohSection = ZenohSection()
    log: LogSection = LogSection()
    viz: VizSection = VizSection()
    world: WorldSection = WorldSection()
    obstacles: tuple[Obstacle, ...] = ()
    capture: CaptureSection = CaptureSection()
    approach: ApproachSection = ApproachSection()
    route: RouteSection = RouteSection()
    transport: TransportSection = TransportSection()
    estimation: EstimationSection = EstimationSection()
    sim: SimSection = SimSection()
    source: str = ""
    notes: tuple[str, ...] = ()  # what the loader changed (e.g. merged polygon vertices)

    def robot(self, robot_id: str) -> RobotConfig:
        for r in self.robots:
            if r.id == robot_id:
                return r
        raise KeyError(f"no robot {robot_id!r} in {self.source or 'config'}; ids: {self.robot_ids}")

    def zenoh_identity(self, robot_id: str | None = None) -> ZenohIdentity:
        """The zenoh identity of a role: a robot's agent (its ``zenoh_*`` keys when it has a
        ``zenoh_user`` or a ``zenoh_certificate``), else the ``[zenoh]`` one (controller,
        recorder, tools)."""
        z = self.zenoh
        if robot_id is not None:
            i = self.robot_ids.index(robot_id)
            r = self.robots[i]
            if r.zenoh_user or r.zenoh_certificate:
                return ZenohIdentity(
                    f"robots[{i}]",
                    r.zenoh_user,
                    r.zenoh_password,
                    r.zenoh_password_file,
                    r.zenoh_certificate,
                    r.zenoh_private_key,
                )
        tls = z.tls or TlsSection()
        return ZenohIdentity(
            "zenoh", z.user, z.password, z.password_file, tls.certificate, tls.private_key
        )

    @property
    def robot_ids(self) -> tuple[str, ...]:
        return tuple(r.id for r in self.robots)

    @property
    def max_robot_radius(self) -> float:
        return max(r.radius for r in self.robots)

    def object_polygon(self) -> np.ndarray:
        """Object polygon in the object frame, counter-clockwise, (n, 2)."""
        return np.asarray(self.object.polygon, dtype=float)

    def obstacle_polygons(self) -> list[np.ndarray]:
        return [np.asarray(o.polygon, dtype=float) for o in self.obstacles]

    def bounds_array(self) -> np.ndarray:
        return np.asarray(self.world.bounds, dtype=float)


def operator_identity(
    cfg: FleetConfig, user: str | None, password_file: str | None
) -> ZenohIdentity | None:
    """The identity given on a tool's command line (``--user``, ``--password-file``: an
    operator), or None for the config's own; InputError when incomplete or the file is missing."""
    if not (user or password_file):
        return None
    if not (user and password_file):
        raise InputError("--user and --password-file go together")
    if not Path(password_file).is_file():
        raise InputError(f"--password-file: no such file: {password_file}")
    return dataclasses.replace(
        cfg.zenoh_identity(),
        path="--user",
        user=user,
        password="",
        password_file=str(Path(password_file).resolve()),
    )


# --------------------------------------------------------------------------- the walker


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if dataclasses.is_dataclass(tp):
        return "a table"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            inner = _type_name(args[0])
            if inner.startswith("an array of "):
                return "an array of arrays of " + inner.removeprefix("an array of ")
            return f"an array of {inner.removeprefix('a ').removeprefix('an ')}s"
        return f"an array of {len(args)} items"
    return str(tp)


def _scalar(tp: type, value: Any, path: str, src: str) -> Any:
    """A bool, int, float or str value checked against its type (a bool is never a number)."""
    is_bool = isinstance(value, bool)
    if tp is bool:
        ok = is_bool
    elif tp is int:
        ok = not is_bool and isinstance(value, int)
    elif tp is float:
        ok = not is_bool and isinstance(value, int | float)
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {value!r}")
    if tp is float:
        if not math.isfinite(value):
            raise ConfigError(src, path, f"expected a finite number, got {value!r}")
        return float(value)
    return value


def _tuple(tp: Any, value: Any, path: str, src: str) -> tuple:
    """A TOML array as a tuple: ``tuple[T, ...]`` of any length or a fixed ``tuple[A, B]``."""
    args = typing.get_args(tp)
    if not isinstance(value, list):
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(args[0], v, f"{path}[{i}]", src) for i, v in enumerate(value))
    if len(value) != len(args):
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {len(value)}: {value!r}")
    return tuple(
        _convert(a, v, f"{path}[{i}]", src)
        for i, (a, v) in enumerate(zip(args, value, strict=True))
    )


def _convert(tp: Any, value: Any, path: str, src: str) -> Any:
    """A TOML value converted to the dataclass field type ``tp`` (ConfigError naming ``path``)."""
    if tp in (bool, int, float, str):
        return _scalar(tp, value, path, src)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(src, path, f"expected a table, got {value!r}")
        return _build(tp, value, path, src)
    if typing.get_origin(tp) is tuple:
        return _tuple(tp, value, path, src)
    if isinstance(tp, types.UnionType):  # an optional key (T | None): present means T
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(inner) == 1:
            return _convert(inner[0], value, path, src)
    raise TypeError(f"unsupported config type {tp}")


def _check_rules(meta: typing.Mapping[str, Any], value: Any, path: str, src: str) -> None:
    if "choices" in meta and value not in meta["choices"]:
        choices = ", ".join(repr(c) for c in meta["choices"])
        raise ConfigError(src, path, f"expected one of {choices}, got {value!r}")
    if "gt" in meta and not value > meta["gt"]:
        raise ConfigError(src, path, f"expected a value > {meta['gt']}, got {value!r}")
    if "min" in meta and not value >= meta["min"]:
        raise ConfigError(src, path, f"expected a value >= {meta['min']}, got {value!r}")
    if "max" in meta and not value <= meta["max"]:
        raise ConfigError(src, path, f"expected a value <= {meta['max']}, got {value!r}")
    if "pattern" in meta and not re.match(meta["pattern"], value):
        raise ConfigError(
            src, path, f"expected letters, digits, '_' or '-' (a bus key segment), got {value!r}"
        )


_NOT_KEYS = ("source", "notes")  # FleetConfig fields the loader fills, never TOML keys


def _build(cls: type, table: dict[str, Any], path: str, src: str) -> Any:
    hints = typing.get_type_hints(cls)
    fields = {
        f.name: f
        for f in dataclasses.fields(cls)
        if f.name not in _NOT_KEYS and not f.metadata.get("internal")
    }
    for key in table:
        if key not in fields:
            where = f"{path}.{key}" if path else key
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            valid = ", ".join(fields)
            raise ConfigError(src, where, f"unknown key{hint} (valid keys: {valid})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        where = f"{path}.{name}" if path else name
        if name not in table:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(src, where, f"missing required key ({_type_name(hints[name])})")
            continue
        value = _convert(hints[name], table[name], where, src)
        _check_rules(f.metadata, value, where, src)
        kwargs[name] = value
    return cls(**kwargs)


# --------------------------------------------------------------------------- cross-field rules


def _polygon(poly: Polygon, path: str, src: str) -> Polygon:
    p = np.asarray(poly, dtype=float)
    if len(p) < 3:
        raise ConfigError(src, path, f"expected a polygon of at least 3 vertices, got {len(p)}")
    bad = geometry.self_intersection(p)
    if bad is not None:
        i, j = bad
        if i == j:
            raise ConfigError(src, path, f"polygon has a zero-length edge at vertex {i}")
        raise ConfigError(
            src, path, f"polygon is not simple: edge {i} crosses edge {j} (self-intersection)"
        )
    area = geometry.signed_area(p)
    if abs(area) < 1e-9:
        raise ConfigError(src, path, "polygon has zero area")
    q = geometry.ensure_ccw(p)
    return tuple((float(x), float(y)) for x, y in q)


def _validate_mavlink(cfg: FleetConfig, i: int, src: str) -> None:
    """A MAVLink robot needs a url and a profile; its system id is unique on its url; an
    ArduRover is differential (GUIDED never moves sideways)."""
    r = cfg.robots[i]
    path = f"robots[{i}]"
    if not r.url:
        raise ConfigError(src, f"{path}.url", "a mavlink robot needs a url")
    if not r.profile:
        raise ConfigError(
            src, f"{path}.profile", f"a mavlink robot needs one of {MAVLINK_PROFILES}"
        )
    if r.gcs_system_id == r.system_id:
        raise ConfigError(
            src, f"{path}.gcs_system_id", f"must differ from the robot's system_id {r.system_id}"
        )
    for j, other in enumerate(cfg.robots[:i]):
        if other.driver == "mavlink" and other.url == r.url and other.system_id == r.system_id:
            raise ConfigError(
                src,
                f"{path}.system_id",
                f"robots[{j}] uses system_id {r.system_id} on the same url {r.url!r}",
            )
    if r.profile == "ardurover" and r.kind != "diff":
        raise ConfigError(
            src,
            f"{path}.kind",
            'an ardurover robot never moves sideways in GUIDED: set kind = "diff"',
        )


def _validate_robot(cfg: FleetConfig, i: int, obstacles: tuple[Obstacle, ...], src: str) -> None:
    """A robot starts inside the room and clear of every obstacle."""
    r = cfg.robots[i]
    path = f"robots[{i}]"
    (x0, y0), (x1, y1) = cfg.world.bounds
    x, y, _ = r.start
    if not (x0 + r.radius <= x <= x1 - r.radius and y0 + r.radius <= y <= y1 - r.radius):
        raise ConfigError(
            src, f"{path}.start", f"robot {r.id!r} at ({x}, {y}) is not inside world.bounds"
        )
    for j, o in enumerate(obstacles):
        if geometry.discs_hit_polygon([[x, y]], r.radius, o.polygon)[0]:
            raise ConfigError(
                src, f"{path}.start", f"robot {r.id!r} at ({x}, {y}) overlaps obstacles[{j}]"
            )
    if r.driver == "mavlink":
        _validate_mavlink(cfg, i, src)


def _validate_robots(cfg: FleetConfig, obstacles: tuple[Obstacle, ...], src: str) -> None:
    if not cfg.robots:
        raise ConfigError(src, "robots", "expected at least one [[robots]] entry")
    seen: dict[str, int] = {}
    for i, r in enumerate(cfg.robots):
        if r.id in seen:
            raise ConfigError(
                src, f"robots[{i}].id", f"duplicate robot id {r.id!r} (also robots[{seen[r.id]}])"
            )
        seen[r.id] = i
        _validate_robot(cfg, i, obstacles, src)
    _check_start_discs(cfg.robots, src)


def _check_start_discs(robots: tuple[RobotConfig, ...], src: str) -> None:
    """No two robots' start discs overlap (touching is fine)."""
    xy = np.array([r.start[:2] for r in robots], dtype=float)
    radii = np.array([r.radius for r in robots], dtype=float)
    gaps = geometry.disc_gaps(xy, radii)
    for j in range(len(robots)):
        for i in range(j):
            if gaps[i, j] < -1e-9:
                a, b = robots[i], robots[j]
                d = float(np.hypot(*(xy[j] - xy[i])))
                raise ConfigError(
                    src,
                    f"robots[{j}].start",
                    f"robot {b.id!r} at {list(b.start[:2])} overlaps robot {a.id!r} "
                    f"(robots[{i}]) at {list(a.start[:2])}: centres {d:.3g} m apart, radii "
                    f"sum {a.radius + b.radius:.3g} m",
                )


_HOSTNAME = re.compile(
    r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9\-]{0,61}[A-Za-z0-9])?"
    r"(\.[A-Za-z0-9]([A-Za-z0-9\-]{0,61}[A-Za-z0-9])?)*$"
)


def endpoint_error(endpoint: Any, listen: bool) -> str | None:
    """Why a zenoh endpoint string is malformed, or None. ``proto/host:port`` for tcp, udp,
    tls and quic (host: IPv4, ``[IPv6]`` or a DNS name; port 1-65535, 0 too where we listen:
    any free port), optionally followed by ``?metadata`` or ``#config``."""
    if not isinstance(endpoint, str) or not endpoint:
        return f"expected a zenoh endpoint string, got {endpoint!r}"
    locator = re.split(r"[?#]", endpoint, maxsplit=1)[0]
    proto, slash, address = locator.partition("/")
    known = ZENOH_IP_PROTOCOLS + ZENOH_OTHER_PROTOCOLS
    if not slash or proto not in known:
        return (
            f"{endpoint!r} is not a zenoh endpoint: expected PROTOCOL/ADDRESS with PROTOCOL one "
            f"of {', '.join(known)} (e.g. 'tcp/127.0.0.1:7447')"
        )
    if not address:
        return f"{endpoint!r}: no address after {proto}/"
    if proto not in ZENOH_IP_PROTOCOLS:
        return None
    host, colon, port = address.rpartition(":")
    if not colon or not host:
        return f"{endpoint!r}: expected {proto}/HOST:PORT (e.g. '{proto}/127.0.0.1:7447')"
    if not port.isdigit() or not (0 if listen else 1) <= int(port) <= 65535:
        least = 0 if listen else 1
        return f"{endpoint!r}: port {port!r} is not a number in {least}..65535"
    problem = _host_error(host)
    return f"{endpoint!r}: {problem}" if problem else None


def _host_error(host: str) -> str | None:
    """Why an endpoint's host is not an IPv4 address, a bracketed IPv6 one or a DNS name."""
    if host.startswith("["):
        try:
            if not host.endswith("]"):
                raise ValueError(host)
            ipaddress.IPv6Address(host[1:-1].split("%")[0])
        except ValueError:
            return f"{host!r} is not a bracketed IPv6 address"
        return None
    if re.fullmatch(r"[0-9.]+", host):
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            return f"{host!r} is not an IPv4 address"
        return None
    if not _HOSTNAME.match(host):
        return f"{host!r} is not a host name or IP address (IPv6 goes in [])"
    return None


def _check_zenoh(section: ZenohSection, src: str) -> None:
    for key in ("listen", "connect"):
        for i, endpoint in enumerate(getattr(section, key)):
            problem = endpoint_error(endpoint, listen=key == "listen")
            if problem:
                raise ConfigError(src, f"zenoh.{key}[{i}]", problem)


def log_dir_problem(directory: str | Path) -> str | None:
    """Why logs cannot be written in ``directory`` (created if missing), or None. Probes with a
    temporary file; creates nothing that stays."""
    d = Path(directory)
    probe = d
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        return f"{str(probe)!r} is not a directory (log files go in {str(d)!r})"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{str(probe)!r} is not writable (log files go in {str(d)!r})"
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as exc:
        return f"cannot write in {str(probe)!r}: {exc.strerror or exc}"
    return None


def edge_node_counts(polygon: Any, spacing: float) -> np.ndarray:
    """Capture candidate nodes per edge at ``spacing``: max(1, floor(length / spacing)), as
    floats (a tiny spacing gives huge counts, never an overflow)."""
    p = np.asarray(polygon, dtype=float)
    lengths = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    with np.errstate(over="ignore"):
        return np.maximum(1.0, np.floor(lengths / spacing + 1e-9))


def capture_budget_error(polygon: Any, spacing: float) -> str | None:
    """Why ``spacing`` gives the capture planner more nodes than its budget, or None."""
    n = float(edge_node_counts(polygon, spacing).sum())
    if n <= CAPTURE_NODE_BUDGET:
        return None
    p = np.asarray(polygon, dtype=float)
    per = float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum())
    least = per / (CAPTURE_NODE_BUDGET - len(p))
    return (
        f"{spacing:g} m gives {n:.4g} candidate nodes on the object's boundary (perimeter "
        f"{per:.4g} m); the capture planner's budget is {CAPTURE_NODE_BUDGET}: "
        f"use capture.spacing >= {least:.3g}"
    )


def merge_vertices(poly: Any, tol: float = 1e-9) -> tuple[np.ndarray, int, int]:
    """The polygon without repeated vertices (closer than ``tol`` m, a closing copy of the first
    one included) and without vertices in the middle of a straight edge (|sin| of the turn below
    ``tol``, the edges going on the same way): (vertices, duplicates removed, collinear removed).
    The shape is unchanged; what changes is what "one robot per edge" counts."""
    p = np.asarray(poly, dtype=float)
    dup = col = 0
    changed = True
    while changed and len(p) > 3:
        changed = False
        step = np.roll(p, -1, axis=0) - p  # edge i: p[i] -> p[i+1]
        length = np.linalg.norm(step, axis=1)
        if np.any(length <= tol):
            i = int(np.argmax(length <= tol))
            p = np.delete(p, i + 1 if i + 1 < len(p) else i, axis=0)  # keep the first vertex
            dup, changed = dup + 1, True
            continue
        prev = np.roll(step, 1, axis=0)  # edge arriving at vertex i
        cross = prev[:, 0] * step[:, 1] - prev[:, 1] * step[:, 0]
        straight = (np.abs(cross) <= tol * np.roll(length, 1) * length) & (
            (prev * step).sum(axis=1) > 0
        )
        if np.any(straight):
            p = np.delete(p, int(np.argmax(straight)), axis=0)
            col, changed = col + 1, True
    return p, dup, col


def _object(cfg: FleetConfig, src: str) -> tuple[ObjectSection, tuple[str, ...]]:
    """The object section with its polygon merged (duplicate and collinear vertices, noted),
    validated and within the capture planner's node budget."""
    merged, dup, col = merge_vertices(cfg.object.polygon)
    notes = cfg.notes
    if dup or col:
        notes += (
            f"object.polygon: merged {dup} duplicate and {col} collinear vertices "
            f"({len(cfg.object.polygon)} -> {len(merged)}; the capture's one robot per edge "
            "counts the merged edges)",
        )
    obj = dataclasses.replace(cfg.object, polygon=_polygon(merged, "object.polygon", src))
    budget = capture_budget_error(obj.polygon, cfg.capture.spacing)
    if budget:
        raise ConfigError(src, "capture.spacing", budget)
    return obj, notes


def _validate(cfg: FleetConfig, src: str) -> FleetConfig:
    """Cross-field rules, after every key was checked on its own."""
    (x0, y0), (x1, y1) = cfg.world.bounds
    if not (x1 > x0 and y1 > y0):
        raise ConfigError(
            src, "world.bounds", "expected [[xmin, ymin], [xmax, ymax]] with max > min"
        )
    obstacles = tuple(
        dataclasses.replace(o, polygon=_polygon(o.polygon, f"obstacles[{i}].polygon", src))
        for i, o in enumerate(cfg.obstacles)
    )
    obj, notes = _object(cfg, src)
    _check_zenoh(cfg.zenoh, src)
    _validate_robots(cfg, obstacles, src)
    _check_object_poses(obj, obstacles, cfg.world.bounds, src)
    check_route_grid(cfg.world.bounds, cfg.route, src)
    cfg = _validate_zenoh(cfg, src)
    return dataclasses.replace(cfg, obstacles=obstacles, object=obj, source=src, notes=notes)


# --------------------------------------------------------------------------- zenoh security


def _abspath(value: str, src: str) -> str:
    """A file named in the config: relative to the config file's folder (else the cwd)."""
    if not value:
        return value
    p = Path(value).expanduser()
    if not p.is_absolute():
        base = Path(src).parent if src and Path(src).is_file() else Path.cwd()
        p = base / p
    return str(p)


def _check_identity(src: str, path: str, user: str, password: str, password_file: str) -> None:
    """A user comes with exactly one of a password or a password file, and vice versa."""
    u, pw, pf = (f"{path}{k}" for k in ("user", "password", "password_file"))
    if password and password_file:
        raise ConfigError(src, pf, f"give {pw} or {pf}, not both")
    if (password or password_file) and not user:
        raise ConfigError(src, u, f"missing: {pw if password else pf} is set without a user")
    if user and not (password or password_file):
        raise ConfigError(src, pw, f"{u} = {user!r} needs a password or a password_file")
    if ":" in user:
        raise ConfigError(src, u, f"a zenoh user name cannot contain ':', got {user!r}")


def _zenoh_robots(cfg: FleetConfig, src: str) -> tuple[RobotConfig, ...]:
    robots = []
    for i, r in enumerate(cfg.robots):
        p = f"robots[{i}]."
        _check_identity(src, p + "zenoh_", r.zenoh_user, r.zenoh_password, r.zenoh_password_file)
        if bool(r.zenoh_certificate) != bool(r.zenoh_private_key):
            raise ConfigError(
                src, p + "zenoh_private_key", "zenoh_certificate and zenoh_private_key go together"
            )
        robots.append(
            dataclasses.replace(
                r,
                zenoh_password_file=_abspath(r.zenoh_password_file, src),
                zenoh_certificate=_abspath(r.zenoh_certificate, src),
                zenoh_private_key=_abspath(r.zenoh_private_key, src),
            )
        )
    return tuple(robots)


def _zenoh_tls(z: ZenohSection, src: str) -> TlsSection | None:
    tls = z.tls
    if tls is None:
        return None
    if not tls.root_ca:
        raise ConfigError(src, "zenoh.tls.root_ca", "missing: the CA that signs the certificates")
    if bool(tls.certificate) != bool(tls.private_key):
        raise ConfigError(src, "zenoh.tls.private_key", "certificate and private_key go together")
    if z.listen and not tls.certificate:
        raise ConfigError(src, "zenoh.tls.certificate", "missing: the listening hub's certificate")
    for key in ("listen", "connect"):
        for j, ep in enumerate(getattr(z, key)):
            if not ep.startswith("tls/"):
                raise ConfigError(
                    src,
                    f"zenoh.{key}[{j}]",
                    f"with zenoh.tls only tls/ endpoints are accepted, got {ep!r} "
                    f"(write 'tls/{ep.split('/', 1)[-1]}')",
                )
    return TlsSection(
        certificate=_abspath(tls.certificate, src),
        private_key=_abspath(tls.private_key, src),
        root_ca=_abspath(tls.root_ca, src),
        mtls=tls.mtls,
    )


def _zenoh_acl(cfg: FleetConfig, src: str) -> tuple[str, str]:
    """(zenoh.acl with a file made absolute, the generated block of a profile or "")."""
    z, acl = cfg.zenoh, cfg.zenoh.acl
    if acl in ACL_PROFILES:
        if not z.user:
            raise ConfigError(
                src, "zenoh.user", f"the {acl!r} ACL profile needs the controller's identity"
            )
        if not z.secured:
            raise ConfigError(
                src,
                "zenoh.acl",
                f"the {acl!r} ACL profile names users: set zenoh.auth_dictionary so the hub "
                "knows who connects",
            )
        for i, r in enumerate(cfg.robots):
            if not r.zenoh_user:
                raise ConfigError(
                    src,
                    f"robots[{i}].zenoh_user",
                    f"the {acl!r} ACL profile needs robot {r.id!r}'s own identity",
                )
        from controller.acl import acl_for

        return acl, json.dumps(acl_for(cfg))
    if acl and not acl.endswith((".json5", ".json")):
        close = difflib.get_close_matches(acl, ACL_PROFILES, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ConfigError(
            src,
            "zenoh.acl",
            f"expected a profile ({', '.join(ACL_PROFILES)}) or a .json5 file, got {acl!r}{hint}",
        )
    return _abspath(acl, src), ""


def _validate_zenoh(cfg: FleetConfig, src: str) -> FleetConfig:
    """The security keys of ``[zenoh]`` and ``[[robots]]``: identities are complete, TLS runs
    on tls/ endpoints only, an ACL profile has every identity it names; file paths made
    absolute (their existence is checked when a session needs them: controller/io/bus.py)."""
    z = cfg.zenoh
    _check_identity(src, "zenoh.", z.user, z.password, z.password_file)
    for j, op in enumerate(z.operators):
        if not op or ":" in op:
            raise ConfigError(src, f"zenoh.operators[{j}]", f"expected a user name, got {op!r}")
    cfg = dataclasses.replace(cfg, robots=_zenoh_robots(cfg, src))
    acl, block = _zenoh_acl(cfg, src)
    zenoh = dataclasses.replace(
        z,
        config_file=_abspath(z.config_file, src),
        password_file=_abspath(z.password_file, src),
        auth_dictionary=_abspath(z.auth_dictionary, src),
        tls=_zenoh_tls(z, src),
        acl=acl,
        acl_block=block,
    )
    return dataclasses.replace(cfg, zenoh=zenoh)


def _polygons_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two simple polygons share a point (touching counts)."""
    ea, eb = np.roll(a, -1, axis=0), np.roll(b, -1, axis=0)
    if geometry.segments_intersect(a[:, None], ea[:, None], b[None], eb[None]).any():
        return True
    return bool(geometry.points_in_polygon(a[:1], b)[0] or geometry.points_in_polygon(b[:1], a)[0])


def _check_object_poses(
    obj: ObjectSection, obstacles: tuple[Obstacle, ...], bounds: tuple[Point, Point], src: str
) -> None:
    """object.start and object.goal place the object inside the bounds, clear of obstacles."""
    (x0, y0), (x1, y1) = bounds
    for key in ("start", "goal"):
        pose = getattr(obj, key)
        if pose is None:  # no goal: a capture job
            continue
        world_poly = geometry.transform(np.asarray(obj.polygon), pose)
        if (
            world_poly[:, 0].min() < x0
            or world_poly[:, 0].max() > x1
            or world_poly[:, 1].min() < y0
            or world_poly[:, 1].max() > y1
        ):
            raise ConfigError(src, f"object.{key}", "the object placed there leaves world.bounds")
        for j, o in enumerate(obstacles):
            if _polygons_overlap(world_poly, np.asarray(o.polygon, dtype=float)):
                raise ConfigError(
                    src,
                    f"object.{key}",
                    f"the object placed at {list(pose)} overlaps obstacles[{j}]",
                )


def _cells(extent: float, resolution: float) -> int:
    return int(math.ceil(extent / resolution - 1e-9))


def check_route_grid(bounds: Any, route: RouteSection, src: str = "") -> None:
    """The route grids over ``bounds`` fit their budgets (:data:`ROUTE_MAX_STATES` object states,
    :data:`ROBOT_ROUTE_MAX_CELLS` robot cells); raises ConfigError naming the key."""
    (x0, y0), (x1, y1) = bounds
    nx, ny = _cells(x1 - x0, route.resolution), _cells(y1 - y0, route.resolution)
    states = nx * ny * route.heading_bins
    if states > ROUTE_MAX_STATES:
        raise ConfigError(
            src,
            "route.resolution",
            f"{route.resolution} m with route.heading_bins = {route.heading_bins} gives "
            f"{nx} x {ny} x {route.heading_bins} = {states / 1e6:.1f} M route states over "
            f"world.bounds, above the budget of {ROUTE_MAX_STATES / 1e6:.0f} M (minutes and "
            "gigabytes per plan); use a coarser route.resolution or fewer route.heading_bins",
        )
    rx = _cells(x1 - x0, route.robot_resolution)
    ry = _cells(y1 - y0, route.robot_resolution)
    if rx * ry > ROBOT_ROUTE_MAX_CELLS:
        raise ConfigError(
            src,
            "route.robot_resolution",
            f"{route.robot_resolution} m gives {rx} x {ry} robot route cells over world.bounds, "
            f"above the budget of {ROBOT_ROUTE_MAX_CELLS} (the robots' routes are planned "
            "during the run); use a coarser route.robot_resolution",
        )


def parse_table(cls: type, table: Any, path: str, source: str = "") -> Any:
    """Validate a TOML table against a config dataclass (unknown keys, types, ranges), as the
    loader does for fleet.toml; raises ConfigError naming ``source`` and the key path."""
    return _convert(cls, table, path, source)


def override(section: Any, values: dict[str, Any], source: str, prefix: str = "") -> Any:
    """A copy of a config section with some fields replaced, each checked by the field's rules
    (e.g. command-line overrides); raises ConfigError naming ``prefix + key``."""
    hints = typing.get_type_hints(type(section))
    fields = {f.name: f for f in dataclasses.fields(section)}
    checked = {}
    for key, value in values.items():
        where = f"{prefix}{key}"
        value = _convert(hints[key], value, where, source)
        _check_rules(fields[key].metadata, value, where, source)
        checked[key] = value
    return dataclasses.replace(section, **checked)


def validated_polygon(poly: Any, path: str, source: str = "") -> Polygon:
    """A simple polygon of >= 3 vertices and non-zero area, counter-clockwise (ConfigError if
    not, naming ``path``)."""
    if isinstance(poly, tuple | list):
        poly = [list(v) if isinstance(v, tuple) else v for v in poly]
    p = _convert(Polygon, poly, path, source)
    return _polygon(p, path, source)


def parse_config(data: dict[str, Any], source: str = "") -> FleetConfig:
    """Validate a parsed TOML document into a FleetConfig (raises ConfigError)."""
    cfg = _build(FleetConfig, data, "", source)
    return _validate(cfg, source)


def load_config(path: str | Path) -> FleetConfig:
    """Read and validate a fleet.toml (raises ConfigError naming the file and key path)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(str(p), "", f"cannot read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(
            str(p), "", f"not a text file (not UTF-8 at byte {exc.start}): expected TOML"
        ) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(p), "", f"not valid TOML: {exc}") from exc
    return parse_config(data, str(p))


# never written to logs or --json: passwords (a password_file is named, not read)
_SECRETS = ("password", "zenoh_password")
REDACTED = "<redacted>"


def config_to_dict(cfg: FleetConfig) -> dict[str, Any]:
    """The config as plain data (for logs and --json); tuples become lists. The loader's notes
    and unset optional keys (``object.goal`` None: TOML has no null) are left out: the data
    must load again. Passwords are written as ``<redacted>`` (a log or --json output is no
    place for them): such a config loads again but authenticates only with the original."""

    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return {
                f.name: REDACTED
                if f.name in _SECRETS and getattr(v, f.name)
                else conv(getattr(v, f.name))
                for f in dataclasses.fields(v)
                if f.name != "notes"
                and not f.metadata.get("internal")
                and getattr(v, f.name) is not None
            }
        if isinstance(v, tuple | list):
            return [conv(x) for x in v]
        return v

    return conv(cfg)
