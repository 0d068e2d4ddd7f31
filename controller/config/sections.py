"""The sections of fleet.toml as frozen dataclasses, their rules in field metadata, and the
registries of valid names (what each name-valued key accepts).

Units are SI unless the key's name says otherwise (``_deg``, ``_hz``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller.config.driver_sections import (
    DRIVER_SPECS,
    DRIVERS,
    DriverSpec,
    MavlinkSection,
    Ros2Section,
    _flat,
)
from controller.config.load import ConfigError, InputError, _rule

# Registries by name. Kept here (not in drivers/) so config validation needs no driver import.
# Drivers: DRIVER_SPECS (below, with their sub-tables); their classes: controller/runtime/wiring.py
ROBOT_KINDS = ("omni", "diff")
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
# the dry run's bus: "private" a free 127.0.0.1 port of its own (two runs side by side), or
# "config" the [zenoh] endpoints as written (tools attach to the run there)
SIM_BUSES = ("private", "config")
OBJECT_STARTS = ("resume", "now")  # sim.object_start: when `fleet world` begins the object's path
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
#: s: the shortest physics step accepted (sim.timestep); the longest is one control tick
MIN_TIMESTEP = 1e-4

Point = tuple[float, float]
Pose = tuple[float, float, float]
Polygon = tuple[Point, ...]


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
    # s the control tick (sample, estimate, execute the plan, safety, publish) may take; 0: 40 %
    # of the period. A tick over it is counted (``over_budget``) and logged
    tick_budget: float = _rule(0.0, min=0, max=10)
    # s a fleet-wide silence (two or more robots missing at once: a hub, world or network
    # outage) may last before its missing robots count as lost; the mission pauses meanwhile
    outage_grace: float = _rule(3.0, min=0, max=600)
    # where the hub and the daemon keep the latched e-stop across restarts and power cuts
    # (``estop-<fleet>-hub.json``, ``-controller.json``), relative to the config file's folder;
    # empty: ``log.state_dir`` if set (the older key, relative to the working folder as before),
    # else ``state/`` beside the config file - never the log folder, which fills up by design
    state_dir: str = _rule("")

    @property
    def period(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def budget(self) -> float:
        """The tick budget, s (``tick_budget``, or 40 % of the period)."""
        return self.tick_budget or 0.4 * self.period


@dataclass(frozen=True, kw_only=True)
class PlannerSection:
    """The planner worker (``controller.runtime.planner``): each planner's latency budget in
    control ticks — the dry run applies a plan asked for at sim time t at t + that many ticks
    (reproducible whatever the machine's load); the lab daemon applies it when it is computed
    and counts it ``late`` past the budget — and ``timeout`` (s) after which a lab plan is
    given up (the robots hold). Defaults from ``bench/loop.py``'s measured p99 at 20 Hz."""

    transport_latency_ticks: int = _rule(6, min=0, max=10_000)
    route_latency_ticks: int = _rule(10, min=0, max=10_000)
    rearrange_latency_ticks: int = _rule(4, min=0, max=10_000)
    capture_latency_ticks: int = _rule(10, min=0, max=10_000)
    # the approach's detours around static obstacles (a robot roadmap and A* per blocked robot)
    detour_latency_ticks: int = _rule(4, min=0, max=10_000)
    timeout: float = _rule(10.0, gt=0, max=3600)

    def latency_ticks(self) -> dict[str, int]:
        return {
            "transport": self.transport_latency_ticks,
            "route": self.route_latency_ticks,
            "rearrange": self.rearrange_latency_ticks,
            "capture": self.capture_latency_ticks,
            "detour": self.detour_latency_ticks,
        }


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
    # the e-stop's second path (docs/lab/safety.md): endpoints the daemon also listens on, a
    # router of its own for the e-stop alone; every agent and fleet estop/resume connect there
    # too, so an e-stop reaches every robot with the hub hung or dead. Empty: the hub only
    estop_listen: tuple[str, ...] = _rule(())
    # s: the longest a session waits between attempts to reach a lost ``connect`` endpoint
    # (the hub restarted): it retries after 0.25 s, then doubling up to this; 0: zenoh's own
    # back-off (1 s, doubling up to 4 s), which let a hub restart take seconds longer to heal
    # than the hub took to come back (bench/hub_restart.py)
    reconnect_s: float = _rule(1.0, min=0, max=60)
    gossip_scouting: bool = _rule(False)
    # Security (docs/lab/secure.md). Files are checked when a session that
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
    # bytes: a received payload larger than this is dropped unread (counted as oversize)
    max_payload: int = _rule(65536, min=1024, max=64 * 1024 * 1024)
    # samples kept per key in a subscriber's inbox (a pose key normally holds 1-2 per tick); a
    # flood drops the oldest (inbox_overflow); the lockstep dry run's inboxes are unbounded
    inbox_depth: int = _rule(8, min=1, max=1_000_000)
    # samples/s a key may bring into a bounded inbox (bursts of 0.25 s allowed); what comes
    # faster is dropped unread and counted (rate_limited): a robot flooding its own pose key
    # costs the loop little. Above any real sensor's rate (motion capture: 100-360 Hz; the
    # robots' poses: 10-50 Hz); 0: no limit. Lossless inboxes (lockstep, e-stops) never limit.
    key_rate_hz: float = _rule(1000.0, min=0, max=1_000_000)

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
    # the older key of ``fleet.state_dir`` (still obeyed when that is empty); empty: the
    # default of ``fleet.state_dir`` (no longer ``dir``)
    state_dir: str = _rule("")
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
class Ros2GraphSection:
    """``[ros2_graph]``: the lab daemon shows the fleet to a ROS 2 graph over rmw_zenoh, no
    bridge: ``/tf`` (``tf2_msgs/TFMessage``, a frame ``<robot id>/base_link`` per robot and
    ``object`` under ``frame_id``, REP 105), each robot's and the object's estimated pose
    (``geometry_msgs/PoseStamped`` on ``<namespace>/<robot id>/pose``, ``<namespace>/object/
    pose``) and the job's phase (``std_msgs/String`` on ``<namespace>/phase``), at ``rate_hz``,
    with rmw_zenoh's liveliness tokens, so ``ros2 topic list``, RViz and rosbag2 see them."""

    enabled: bool = _rule(False)
    domain_id: int = _rule(0, min=0, max=232)  # ROS_DOMAIN_ID
    namespace: str = _rule("/fleet")
    node_name: str = _rule("fleet_controller")
    frame_id: str = _rule("map")  # the world frame's name on the graph
    rate_hz: float = _rule(10.0, gt=0, max=100)
    # the ROS graph's zenoh router (rmw_zenohd) and how the daemon joins it
    connect: tuple[str, ...] = _rule(("tcp/127.0.0.1:7447",))
    mode: str = _rule("client", choices=("client", "peer"))


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
    # the GA of the capture points and of Eq. 5's pushers: ours (a GA plus local search and
    # restarts) or "paper" (Sharma et al.'s as published, MATLAB ga's operators)
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
    # the interception rules: "classic" (a robot meets only an object slower than itself and
    # rides on the object's velocity all the way) or "oncoming" (it also meets an object coming
    # at it as fast or faster, and rides on its velocity only within the last metre: the arrest's
    # speed edge 0.30 -> 0.35 m/s, bench/arrest.py; not the default: with it the default job's
    # transport had two robots touch, 10 um, in pybullet)
    intercept: str = _rule("classic", choices=("classic", "oncoming"))
    # share of the slowest available robot's max_speed: an object this fast or faster is
    # braced: 2-4 robots ahead of it wait on its path at contacts that stop it (the capture set
    # planned again around them), hold their ground, and the rest close in on it at rest
    # (controller/mission/brace.py); 0: never (the rules before; bench/arrest.py)
    brace_share: float = _rule(0.6, min=0, max=10)
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
class ErrorModel:
    """The errors the transport's plans allow for (Yamashita et al., Table 1's condition 2;
    all 0: condition 1, plans that ignore them). ``position``: each robot's motion error,
    ±x, ±y m (the paper's [0.04, 0.01]); ``mass`` and ``friction``: the object's mass and floor
    friction known to ± that share (0.1); ``com``: its centre of mass known to ± that many m
    along each axis (0.01)."""

    # m, ±x and ±y: each robot's motion error; pushes keep its norm from every vertex and
    # robots twice it apart (Yamashita's [0.04, 0.01])
    position: Point = _rule((0.0, 0.0))
    # share, ±: the object's mass; forces planned for the heaviest (0.1)
    mass: float = _rule(0.0, min=0, max=0.9)
    # share, ±: the floor friction; forces planned for the roughest (0.1)
    friction: float = _rule(0.0, min=0, max=0.9)
    # m, ± per axis: the centre of mass off the centroid; pushing sets make the torque either
    # way (0.01)
    com: float = _rule(0.0, min=0, max=1)


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
    # the errors the plans allow for: margins at the contacts and between robots, forces for
    # the heaviest, roughest object (Yamashita's condition 2); all 0: ignore them (condition 1)
    errors: ErrorModel = _rule(ErrorModel())


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
    # fleet run's bus: "private" a free 127.0.0.1 port of its own (two runs side by side), or
    # "config" the [zenoh] endpoints as written (tools attach to the run there)
    bus: str = _rule("private", choices=SIM_BUSES)
    # s per physics step: at least MIN_TIMESTEP (below it a second of sim takes hours) and at
    # most one control tick (1 / fleet.rate_hz), checked after the walk
    timestep: float = _rule(1.0 / 240.0, min=MIN_TIMESTEP, max=1)
    seed: int = _rule(0, min=0)
    pose_noise: PoseNoise = _rule(PoseNoise())
    pose_rate_hz: float = _rule(30.0, gt=0, max=1000)
    object_pose_rate_hz: float = _rule(30.0, gt=0, max=1000)
    dropout: float = _rule(0.0, min=0, max=1)
    outlier_rate: float = _rule(0.0, min=0, max=1)
    outlier_magnitude: float = _rule(0.5, min=0, max=100)
    realtime: bool = _rule(False)
    # s of wall time the lockstep clock waits for the controller's answer (and the controller
    # for the measurements) before it counts a missed tick: a missed tick changes the run, so
    # it is long enough that only a hung controller misses one (at a load of 14 on 2 cores a
    # tick took over 2 s)
    tick_timeout: float = _rule(10.0, gt=0, max=600)
    max_time: float = _rule(300.0, gt=0, max=1e6)
    # the pybullet object as it really is, against what [object] tells the controller (the
    # robustness sweeps of bench/transport_loop.py and bench/transport_compare.py; 1, 1 and
    # (0, 0): the same object)
    object_mass_scale: float = _rule(1.0, gt=0, max=100)
    object_friction_scale: float = _rule(1.0, min=0, max=100)
    object_com_offset: Point = _rule((0.0, 0.0))
    # robot motion errors (Yamashita et al. Table 1: ±0.04 m, ±0.01 m): each robot's pose
    # reports are off its true pose by a fixed offset drawn U(−x, x), U(−y, y) per run, world
    # frame (m); the controller steers the robot that far off where it means it to be
    robot_position_error: Point = _rule((0.0, 0.0))
    # `fleet world` (a rehearsal): when the object's path begins. "resume": at the operator's
    # first resume (the e-stop released by a hub or controller), its drive holding the start
    # pose until then, so a slow bring-up cannot carry it into an obstacle before the job
    # begins; "now": when the world starts. The dry run begins it at sim time 0 either way.
    object_start: str = _rule("resume", choices=OBJECT_STARTS)


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
    # per-driver sub-tables (DRIVER_SPECS): [robots.mavlink]; the flat keys merge into them
    mavlink: MavlinkSection = _rule(MavlinkSection())
    ros2: Ros2Section = _rule(Ros2Section())
    # the robot agent's own zenoh identity (else the [zenoh] one): the lab ACL profile lets it
    # put only this robot's pose/event and receive only this robot's commands
    zenoh_user: str = _rule("")
    zenoh_password: str = _rule("")
    zenoh_password_file: str = _rule("")
    zenoh_certificate: str = _rule("")  # mutual TLS: this robot's own certificate and key
    zenoh_private_key: str = _rule("")

    # the flat keys, readable as before the sub-tables
    url = _flat("mavlink", "url")
    system_id = _flat("mavlink", "system_id")
    profile = _flat("mavlink", "profile")
    link_timeout = _flat("mavlink", "link_timeout")
    arm = _flat("mavlink", "arm")
    hold_on_close = _flat("mavlink", "hold_on_close")
    max_vehicle_timeout = _flat("mavlink", "max_vehicle_timeout")
    gcs_system_id = _flat("mavlink", "gcs_system_id")
    telemetry_hz = _flat("mavlink", "telemetry_hz")

    @property
    def spec(self) -> DriverSpec:
        """This robot's driver entry."""
        return DRIVER_SPECS[self.driver]

    @classmethod
    def merge_table(cls, table: dict[str, Any], path: str, src: str) -> dict[str, Any]:
        """The ``[[robots]]`` table with each driver's flat keys moved into its sub-table; a
        key given both ways with different values is an error naming both paths, and so is a
        sub-table of another driver than the robot's (a forgotten ``driver = "mavlink"`` would
        otherwise run a vehicle's entry as a simulated robot)."""
        out = dict(table)
        driver = table.get("driver", "sim")
        for name, spec in DRIVER_SPECS.items():
            if spec.section is not None and name in table and driver != name:
                raise ConfigError(
                    src,
                    f"{path}.{name}",
                    f"a {name} sub-table on a robot with driver = {driver!r}: set "
                    f'driver = "{name}" or remove the sub-table',
                )
            moved = {k: out.pop(k) for k in spec.flat_keys if k in out}
            if not moved:
                continue
            sub = out.get(name, {})
            if not isinstance(sub, dict):
                continue  # the walker reports "expected a table"
            for k, v in moved.items():
                if k in sub and sub[k] != v:
                    raise ConfigError(
                        src,
                        f"{path}.{name}.{k}",
                        f"given as {path}.{k} = {v!r} and {path}.{name}.{k} = {sub[k]!r}: "
                        "set it once (the sub-table is the newer form)",
                    )
            out[name] = {**moved, **sub}
        return out


@dataclass(frozen=True, kw_only=True)
class FleetConfig:
    fleet: FleetSection
    object: ObjectSection
    robots: tuple[RobotConfig, ...]
    zenoh: ZenohSection = ZenohSection()
    log: LogSection = LogSection()
    viz: VizSection = VizSection()
    ros2_graph: Ros2GraphSection = Ros2GraphSection()
    world: WorldSection = WorldSection()
    obstacles: tuple[Obstacle, ...] = ()
    capture: CaptureSection = CaptureSection()
    approach: ApproachSection = ApproachSection()
    route: RouteSection = RouteSection()
    transport: TransportSection = TransportSection()
    estimation: EstimationSection = EstimationSection()
    sim: SimSection = SimSection()
    planner: PlannerSection = PlannerSection()
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
