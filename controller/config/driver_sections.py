"""The drivers as the config knows them: name → sub-table ``[robots.<name>]``, its validation,
its ACL needs and its advice (:class:`DriverSpec`, :data:`DRIVER_SPECS`). The driver classes
are registered under the same names in controller/runtime/wiring.py (the only importer of
drivers/). Adding a driver: its sub-table dataclass and ``register_driver`` here, its class
there, its module in drivers/.
"""

from __future__ import annotations

import re
import typing
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from controller.config.load import ConfigError, _rule

if TYPE_CHECKING:
    from controller.config.sections import FleetConfig

MAVLINK_PROFILES = ("ardurover", "px4")


# --------------------------------------------------------------------------- drivers


@dataclass(frozen=True, kw_only=True)
class MavlinkSection:
    """``[robots.mavlink]``: a MAVLink rover (drivers/mavlink/). Its keys are also accepted
    flat in ``[[robots]]`` (as before the sub-table), except the newer ``heartbeat_hz`` and
    ``fs_timeout``."""

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
    # Hz: the LOCAL_POSITION_NED/ATTITUDE rate asked; a vehicle that refuses it (ArduPilot DENIES
    # 50 Hz at its default SCHED_LOOP_RATE) is asked step by step for less, down to
    # telemetry_min_hz; the rate granted is logged
    telemetry_hz: float = _rule(50.0, min=1, max=1000)
    telemetry_min_hz: float = _rule(5.0, min=1, max=1000)
    # an e-stop or watchdog stop sends the zero setpoint at once and switches the vehicle to
    # its hold mode (ArduPilot HOLD, PX4 AUTO.LOITER): "at_rest" once it reports it stopped (the
    # speed controller brakes in GUIDED; ArduRover's HOLD only cuts the throttle, so an
    # ackermann or omni rover coasts in it), "now" at once, "off" never; the next command
    # switches it back to GUIDED / OFFBOARD
    stop_hold: str = _rule("at_rest", choices=("at_rest", "now", "off"))
    # an e-stop or watchdog stop also disarms the vehicle (re-armed on the next command when
    # ``arm`` is set)
    disarm_on_stop: bool = _rule(False)
    # Hz: our GCS HEARTBEAT to the vehicle (what its GCS failsafe counts)
    heartbeat_hz: float = _rule(1.0, min=0.2, max=50)
    # s: the vehicle's GCS failsafe timeout as set on it (ArduRover FS_TIMEOUT), for fleet check
    # to compare with heartbeat_hz (0: not given)
    fs_timeout: float = _rule(0.0, min=0, max=3600)


ROS2_CMD_TYPES = ("twist", "twist_stamped")
ROS2_POSE_TYPES = ("odometry", "pose_stamped")
ROS2_ROUTER = "tcp/127.0.0.1:7447"  # rmw_zenohd's default endpoint on the robot's host
#: the oldest rmw_zenoh release of each distro we speak to: the 33-byte sample attachment
#: (sequence, source time, 16-byte GID; rmw_zenoh #605) and zenoh 1.x; older robots read our
#: commands' attachment as malformed. drivers/ros2/keys.py has the wire format.
RMW_ZENOH_MIN = {"humble": (0, 1, 2), "jazzy": (0, 2, 4), "rolling": (0, 6, 0)}
_RMW_ZENOH = re.compile(r"^\s*([a-z]+)\s+(\d+)\.(\d+)\.(\d+)\s*$")


def rmw_zenoh_supported() -> str:
    """The supported rmw_zenoh releases, for messages and docs."""
    return ", ".join(f"{d} >= {'.'.join(map(str, v))}" for d, v in RMW_ZENOH_MIN.items())


def rmw_zenoh_problem(value: str) -> str | None:
    """Why a ``ros2.rmw_zenoh`` value (``"<distro> <x.y.z>"``, ``""``: not stated) is refused,
    or None."""
    if not value.strip():
        return None
    m = _RMW_ZENOH.match(value)
    if m is None:
        return f"expected '<distro> <x.y.z>' (e.g. 'jazzy 0.2.5'), got {value!r}"
    distro, version = m.group(1), tuple(int(g) for g in m.groups()[1:])
    least = RMW_ZENOH_MIN.get(distro)
    if least is None:
        return f"unknown ROS 2 distro {distro!r} (supported: {rmw_zenoh_supported()})"
    if version < least:
        return (
            f"rmw_zenoh {distro} {'.'.join(map(str, version))} is not supported: older releases "
            f"use another sample attachment (and older zenoh); supported: {rmw_zenoh_supported()}"
        )
    return None


@dataclass(frozen=True, kw_only=True)
class Ros2Section:
    """``[robots.ros2]``: a ROS 2 robot reached over zenoh with rmw_zenoh's conventions
    (drivers/ros2/). Topics are ROS names, relative ones under ``namespace``."""

    domain_id: int = _rule(0, min=0, max=232)  # ROS_DOMAIN_ID
    namespace: str = _rule("")  # the robot's ROS namespace, e.g. "/tb4_1" ("": the root)
    node_name: str = _rule("")  # our node's name on the robot's graph ("": fleet_driver_<id>)
    cmd_topic: str = _rule("cmd_vel")
    cmd_type: str = _rule("twist", choices=ROS2_CMD_TYPES)
    cmd_frame_id: str = _rule("base_link")  # header.frame_id of a TwistStamped
    pose_topic: str = _rule("odom")
    pose_type: str = _rule("odometry", choices=ROS2_POSE_TYPES)
    # the pose frame's (odom, REP 105, or a mocap map) pose in our world: x, y (m), yaw (rad)
    odom_to_world: tuple[float, float, float] = _rule((0.0, 0.0, 0.0))
    # a pose's time: its header stamp (clocks synchronised) or our clock when it arrives
    time_source: str = _rule("header", choices=("header", "receipt"))
    # m, rad: a pose's standard deviations when its message gives no covariance
    sigma_xy: float = _rule(0.02, gt=0, max=10)
    sigma_theta: float = _rule(0.02, gt=0, max=10)
    # the zenoh router of the robot's ROS graph (rmw_zenohd) and how we join it
    connect: tuple[str, ...] = _rule((ROS2_ROUTER,))
    mode: str = _rule("client", choices=("client", "peer"))
    # s without a fresh pose before the link is lost (a pose older than fleet.stale_after is
    # dropped at once: the robot is stale, commanded zero, and its agent's watchdog stops it); as
    # the MAVLink link_timeout: a Wi-Fi hiccup is not a loss. A lost link is held: the agent
    # keeps the robot stopped and stays up, link_restored when fresh poses return
    link_timeout: float = _rule(2.5, gt=0, max=60)
    # the robot's rmw_zenoh release, "<distro> <x.y.z>" (`apt show ros-<distro>-rmw-zenoh-cpp`),
    # checked against RMW_ZENOH_MIN; "": not stated (assumed supported; the driver logs an
    # error when the robot's samples carry another attachment than the supported releases')
    rmw_zenoh: str = _rule("")


#: an ArduRover's FS_TIMEOUT must span this many of our heartbeat periods (one lost or late
#: heartbeat must not trip the failsafe: at 1 Hz, FS_TIMEOUT = 1 s flaps)
FS_TIMEOUT_PERIODS = 3.0


@dataclass(frozen=True)
class DriverSpec:
    """What the config knows of one driver (``robots[].driver``): its ``[robots.<name>]``
    sub-table and how it is validated, and what its agent needs from the hub's ACL. The driver
    classes themselves are registered in controller/runtime/wiring.py (the only importer of
    drivers/), under the same names.

    ``section``: the sub-table's dataclass (None: the driver has no settings); ``flat_keys``:
    its keys also accepted directly in ``[[robots]]``; ``world_body``: the robot is a body of the
    stand-in world (its pose from the world's sensors), not a vehicle of its own;
    ``validate(cfg, i, src)``: cross-field rules of robot ``i``; ``acl(cfg, robot)``: extra
    (keys its agent puts, keys it is sent) beyond every robot's own; ``notes(cfg, i)``: advice
    for ``fleet check`` (the loader's notes)."""

    name: str
    section: type | None = None
    flat_keys: tuple[str, ...] = ()
    world_body: bool = False
    validate: typing.Callable[[Any, int, str], None] | None = None
    acl: typing.Callable[[Any, Any], tuple[list[str], list[str]]] | None = None
    notes: typing.Callable[[Any, int], tuple[str, ...]] | None = None


DRIVER_SPECS: dict[str, DriverSpec] = {}


def register_driver(spec: DriverSpec) -> DriverSpec:
    """Add a driver's config entry (its name becomes valid for ``robots[].driver``)."""
    if spec.name in DRIVER_SPECS:
        raise ValueError(f"driver {spec.name!r} is already registered")
    DRIVER_SPECS[spec.name] = spec
    return spec


def driver_spec(name: str) -> DriverSpec:
    """The registered driver ``name`` (KeyError naming the valid ones)."""
    try:
        return DRIVER_SPECS[name]
    except KeyError:
        raise KeyError(f"unknown driver {name!r}; expected one of {tuple(DRIVER_SPECS)}") from None


def _sim_acl(cfg: Any, robot: Any) -> tuple[list[str], list[str]]:
    """A sim robot of the shared ``fleet world`` process puts the command it applies and is
    sent its samples (only when the config rehearses that way)."""
    from controller import wire

    if cfg.sim.world != "process":
        return [], []
    fleet = cfg.fleet.name
    return [wire.key("world_cmd", fleet, id=robot.id)], [wire.key("world_pose", fleet, id=robot.id)]


def _flat(driver: str, key: str) -> property:
    """A flat ``[[robots]]`` key read from the robot's ``[robots.<driver>]`` sub-table."""

    def get(self: Any) -> Any:
        return getattr(getattr(self, driver), key)

    get.__doc__ = f"``{driver}.{key}`` (also accepted flat in [[robots]])"
    return property(get)


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
    m = r.mavlink
    least = FS_TIMEOUT_PERIODS / m.heartbeat_hz
    if r.profile == "ardurover" and 0 < m.fs_timeout < least - 1e-9:
        raise ConfigError(
            src,
            f"{path}.mavlink.fs_timeout",
            f"FS_TIMEOUT {m.fs_timeout:g} s is under {FS_TIMEOUT_PERIODS:g} periods of our "
            f"{m.heartbeat_hz:g} Hz heartbeat: one late heartbeat would trip the GCS failsafe; "
            f"set FS_TIMEOUT >= {least:g} s on the vehicle (or raise mavlink.heartbeat_hz)",
        )
    if r.profile == "ardurover" and r.kind != "diff":
        raise ConfigError(
            src,
            f"{path}.kind",
            'an ardurover robot never moves sideways in GUIDED: set kind = "diff"',
        )


def _mavlink_notes(cfg: FleetConfig, i: int) -> tuple[str, ...]:
    """The GCS failsafe an ArduRover needs (docs/lab/mavlink.md) when its FS_TIMEOUT is not
    given (``mavlink.fs_timeout``): at least FS_TIMEOUT_PERIODS of our heartbeat periods."""
    r = cfg.robots[i]
    if r.profile != "ardurover" or r.mavlink.fs_timeout:
        return ()
    hz = r.mavlink.heartbeat_hz
    return (
        f"robots[{i}] ({r.id!r}, ardurover): set FS_GCS_ENABLE = 1 and FS_TIMEOUT >= "
        f"{FS_TIMEOUT_PERIODS / hz:g} s on the vehicle ({FS_TIMEOUT_PERIODS:g} periods of "
        f"mavlink.heartbeat_hz = {hz:g}); give it as mavlink.fs_timeout to have it checked",
    )


_ROS_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/\S+$")


def _ros_name(value: str, absolute: bool) -> bool:
    """A ROS name: ``/``-separated tokens (letters, digits, ``_``; no leading digit)."""
    if absolute and value.startswith("/"):
        value = value[1:]
    return bool(value) and all(_ROS_TOKEN.match(p) for p in value.split("/"))


def _ros2_topic(ns: str, topic: str) -> str:
    if topic.startswith("/"):
        return topic
    return f"/{ns.strip('/')}/{topic}" if ns.strip("/") else f"/{topic}"


def _check_router(connect: tuple[str, ...], path: str, src: str) -> None:
    """A ROS graph's router endpoints: at least one, each a zenoh endpoint."""
    if not connect:
        raise ConfigError(src, path, "expected at least one zenoh endpoint")
    for k, ep in enumerate(connect):
        if not _ENDPOINT.match(ep):
            raise ConfigError(
                src, f"{path}[{k}]", f"expected a zenoh endpoint like {ROS2_ROUTER!r}, got {ep!r}"
            )


def _validate_ros2(cfg: FleetConfig, i: int, src: str) -> None:
    """ROS names that rmw_zenoh can key, router endpoints, and no two robots commanded on the
    same topic of the same domain."""
    r = cfg.robots[i]
    s = r.ros2
    path = f"robots[{i}].ros2"
    if s.namespace not in ("", "/") and not (
        s.namespace.startswith("/") and _ros_name(s.namespace, True)
    ):
        raise ConfigError(
            src, f"{path}.namespace", f"expected an absolute ROS namespace (e.g. '/tb4_1'), got "
            f"{s.namespace!r}",
        )  # fmt: skip
    if s.node_name and not _ROS_TOKEN.match(s.node_name):
        raise ConfigError(src, f"{path}.node_name", f"not a ROS node name: {s.node_name!r}")
    for key in ("cmd_topic", "pose_topic", "cmd_frame_id"):
        value = getattr(s, key)
        if not _ros_name(value, key != "cmd_frame_id"):
            raise ConfigError(src, f"{path}.{key}", f"not a ROS name: {value!r}")
    _check_router(s.connect, f"{path}.connect", src)
    problem = rmw_zenoh_problem(s.rmw_zenoh)
    if problem is not None:
        raise ConfigError(src, f"{path}.rmw_zenoh", problem)
    if _ros2_topic(s.namespace, s.cmd_topic) == _ros2_topic(s.namespace, s.pose_topic):
        raise ConfigError(src, f"{path}.pose_topic", "the same topic as cmd_topic")
    mine = (s.domain_id, _ros2_topic(s.namespace, s.cmd_topic))
    for j, other in enumerate(cfg.robots[:i]):
        o = other.ros2
        if other.driver == "ros2" and (o.domain_id, _ros2_topic(o.namespace, o.cmd_topic)) == mine:
            raise ConfigError(
                src, f"{path}.cmd_topic", f"robots[{j}] is commanded on the same topic "
                f"{mine[1]!r} of ROS domain {mine[0]}: give each robot its namespace",
            )  # fmt: skip


def validate_ros2_graph(cfg: FleetConfig, src: str) -> None:
    """``[ros2_graph]``: ROS names rmw_zenoh can key, and a router that is not the fleet's own
    hub (the ROS graph has its own, rmw_zenohd)."""
    g = cfg.ros2_graph
    if not (g.namespace.startswith("/") and _ros_name(g.namespace, True)):
        raise ConfigError(
            src, "ros2_graph.namespace", f"expected an absolute ROS namespace (e.g. '/fleet'), "
            f"got {g.namespace!r}",
        )  # fmt: skip
    if not _ROS_TOKEN.match(g.node_name):
        raise ConfigError(src, "ros2_graph.node_name", f"not a ROS node name: {g.node_name!r}")
    if not _ros_name(g.frame_id, False):
        raise ConfigError(src, "ros2_graph.frame_id", f"not a ROS frame name: {g.frame_id!r}")
    _check_router(g.connect, "ros2_graph.connect", src)
    for k, ep in enumerate(g.connect):
        if g.enabled and ep in cfg.zenoh.listen:
            raise ConfigError(
                src, f"ros2_graph.connect[{k}]", f"{ep} is the fleet's own hub (zenoh.listen): "
                "give the ROS graph's router, rmw_zenohd (the ROS 2 examples put it on "
                "tcp/127.0.0.1:7448)",
            )  # fmt: skip


def _ros2_notes(cfg: FleetConfig, i: int) -> tuple[str, ...]:
    """An odometry left at the world origin while the robot starts elsewhere: its odometry
    starts at zero where it powers up, so its poses would land at the origin."""
    r = cfg.robots[i]
    s = r.ros2
    if s.pose_type != "odometry" or any(s.odom_to_world) or not any(r.start[:2]):
        return ()
    return (
        f"robots[{i}] ({r.id!r}, ros2): odom_to_world is [0, 0, 0] but start is "
        f"{list(r.start)}: odometry starts at zero where the robot powers up; set "
        "ros2.odom_to_world to its world pose then (usually its start)",
    )


# the built-in drivers (their classes: controller/runtime/wiring.py DRIVER_CLASSES)
register_driver(DriverSpec("sim", world_body=True, acl=_sim_acl))
register_driver(
    DriverSpec(
        "mavlink",
        section=MavlinkSection,
        flat_keys=(
            "url",
            "system_id",
            "profile",
            "link_timeout",
            "arm",
            "hold_on_close",
            "max_vehicle_timeout",
            "gcs_system_id",
            "telemetry_hz",
        ),
        validate=_validate_mavlink,
        notes=_mavlink_notes,
    )
)
register_driver(DriverSpec("ros2", section=Ros2Section, validate=_validate_ros2, notes=_ros2_notes))
DRIVERS = tuple(DRIVER_SPECS)
