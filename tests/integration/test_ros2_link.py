"""The ROS 2 driver against the stand-in robot over loopback zenoh: what a ROS 2 robot sees of
us on the wire (keys, attachments, liveliness tokens; our commands decoded by rosbags, not by
the driver's codec), REP 105 poses placed in the world, and a stale pose as a lost link."""

from __future__ import annotations

import dataclasses
import math

import pytest

from controller.wire import Twist2D
from drivers.base import Capabilities, LinkLost
from drivers.ros2 import keys, msgs
from drivers.ros2.driver import Ros2Driver, Ros2Settings
from drivers.ros2.node import open_session
from tests.support.config import free_port
from tests.support.ros2_robot import StandInRobot, rosbags_decode
from tests.support.wait import wait_for

CAPS = Capabilities("omni", True, 0.5, 2.0, 0.15)


class Link:
    """A stand-in robot (listening peer) and a driver (client) on a loopback port; the driver's
    clock is the robot's time plus ``offset``, its monotonic clock is ``mono[0]``."""

    def __init__(self, settings: Ros2Settings, start=(3.0, 4.0, 0.3), stale_after=0.5):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.settings = dataclasses.replace(settings, connect=(endpoint,))
        self.session = open_session(listen=[endpoint], mode="peer")
        self.robot = StandInRobot(self.session, self.settings, "omni", start)
        self.mono = [100.0]
        self.offset = 0.0
        self.driver = Ros2Driver(
            "r1", CAPS, self.settings, stale_after=stale_after,
            clock=lambda: self.robot.t + self.offset, monotonic=lambda: self.mono[0],
        )  # fmt: skip

    def connect(self) -> None:
        self.driver.open()
        wait_for(self.robot.pub.matching, 10, "the driver's subscription at the robot")
        self.robot.publish()
        self.driver.connect(timeout=5.0)

    def advance(self, dt: float) -> None:
        wait_for(lambda: self.robot.commands_seen() >= self.driver.sent, 5, "the commands")
        self.robot.step(dt)
        self.mono[0] += dt
        self.robot.publish()
        wait_for(lambda: self.driver.samples_seen() >= self.robot.published, 5, "the pose")

    def close(self) -> None:
        self.driver.close()
        self.robot.close()
        self.session.close()


@pytest.fixture
def link(request):
    settings = getattr(request, "param", Ros2Settings(namespace="/tb1"))
    lk = Link(settings)
    lk.connect()
    yield lk
    lk.close()


@pytest.mark.parametrize(
    "link",
    [Ros2Settings(namespace="/tb1"), Ros2Settings(namespace="/tb1", cmd_type="twist_stamped")],
    indirect=True,
    ids=["twist", "twist_stamped"],
)
def test_commands_on_the_wire_as_rmw_zenoh_sends_them(link):
    """Each command: rmw_zenoh's key for the robot's cmd_vel, a CDR payload that rosbags
    decodes to the same velocities, an attachment with a sequence from 1, our clock in ns and
    the GID of our publisher's liveliness token."""
    d, robot = link.driver, link.robot
    type_name = msgs.CMD_TYPES[link.settings.cmd_type]
    assert robot.cmd_key == d.cmd_key == keys.topic_key(0, "/tb1/cmd_vel", type_name)
    for i, (vx, vy, wz) in enumerate([(0.2, 0.0, 0.1), (0.0, -0.1, -0.4), (0.05, 0.05, 0.0)]):
        d.send(Twist2D(t=0.0, vx=vx, vy=vy, wz=wz))
        link.advance(0.1)
        payload, att = robot.raw_commands[-1]
        m = rosbags_decode(type_name, payload)
        tw = m if link.settings.cmd_type == "twist" else m.twist
        assert (tw.linear.x, tw.linear.y, tw.angular.z) == (vx, vy, wz)
        seq, ts, gid = keys.parse_attachment(att)
        assert seq == i + 1
        assert ts == pytest.approx(robot.t * 1e9 - 0.1e9, abs=1e3)  # sent before the step
        assert gid == d._pub.gid == keys.gid(d._pub.token_key)
        if link.settings.cmd_type == "twist_stamped":
            assert m.header.frame_id == "base_link"
            assert m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 == pytest.approx(ts * 1e-9)


def test_the_robot_discovers_our_node_by_its_liveliness_tokens(link):
    replies = link.session.liveliness().get("@ros2_lv/0/**", timeout=5.0)
    tokens = [keys.parse_token(str(r.ok.key_expr)) for r in replies if r.ok is not None]
    ours = [t for t in tokens if t and t["node"] == "fleet_driver_r1"]
    kinds = {(t["kind"], t.get("topic"), t.get("type")) for t in ours}
    assert kinds == {
        ("NN", None, None),
        ("MP", "/tb1/cmd_vel", "geometry_msgs::msg::dds_::Twist_"),
        ("MS", "/tb1/odom", "nav_msgs::msg::dds_::Odometry_"),
    }
    assert all(t["namespace"] == "/tb1" and t["domain"] == "0" for t in ours)
    robot = {(t["kind"], t.get("topic")) for t in tokens if t and t["node"] == "robot_base"}
    assert robot == {("NN", None), ("MS", "/tb1/cmd_vel"), ("MP", "/tb1/odom")}


def test_the_attachment_gid_is_rmw_zenohs_hash_of_our_publishers_token(link):
    """What a ROS 2 receiver gets as ``publisher_gid`` (and ``ros2 topic info -v`` lists) is
    XXH3-128 of the publisher's liveliness key expression, low64 then high64, little endian:
    computed here from the MP token the robot discovers on the wire, not from our own key."""
    import xxhash

    link.driver.send(Twist2D(t=0.0, vx=0.1))
    link.advance(0.05)
    _, _, gid = keys.parse_attachment(link.robot.raw_commands[-1][1])
    replies = link.session.liveliness().get("@ros2_lv/0/*/*/*/MP/**", timeout=5.0)
    (token,) = [
        str(r.ok.key_expr) for r in replies if r.ok is not None and "fleet_driver_r1" in
        str(r.ok.key_expr)
    ]  # fmt: skip
    h = xxhash.xxh3_128_intdigest(token.encode())
    low, high = h % 2**64, h >> 64
    assert gid == low.to_bytes(8, "little") + high.to_bytes(8, "little")


@pytest.mark.parametrize(
    "link",
    [
        Ros2Settings(namespace="/tb1", odom_to_world=(3.0, 4.0, 0.3)),
        Ros2Settings(namespace="/tb1", odom_to_world=(-2.0, 1.0, -2.0), pose_type="pose_stamped"),
    ],
    indirect=True,
    ids=["odometry", "pose_stamped"],
)
def test_odom_poses_are_placed_in_the_world(link):
    """The robot reports its pose in its odom frame; the driver returns the world pose."""
    d = link.driver
    first = d.poll()[-1]
    assert (first.x, first.y, first.theta) == pytest.approx((3.0, 4.0, 0.3))
    assert first.source == "ros2" and first.t == link.robot.t
    d.send(Twist2D(t=0.0, vx=0.2))
    link.advance(1.0)
    m = d.poll()[-1]
    assert (m.x, m.y) == pytest.approx((3.0 + 0.2 * math.cos(0.3), 4.0 + 0.2 * math.sin(0.3)))
    assert m.theta == pytest.approx(0.3)


def test_silence_beyond_link_timeout_is_a_lost_link_and_shorter_is_not(link):
    """A pose stream silent longer than stale_after (0.5 s) leaves the link up (the controller
    sees the robot stale and stops commanding it); silent longer than link_timeout (2.5 s),
    the link is lost."""
    d = link.driver
    assert d.health().ok and link.settings.link_timeout == 2.5
    link.mono[0] += 0.6  # longer than stale_after, a Wi-Fi hiccup
    assert d.health().ok
    d.send(Twist2D(t=0.0, vx=0.0))
    link.mono[0] += 2.0  # 2.6 s of silence in all
    h = d.health()
    assert not h.ok and "no fresh nav_msgs/msg/Odometry" in h.detail
    with pytest.raises(LinkLost):
        d.send(Twist2D(t=0.0, vx=0.1))
    link.advance(0.05)  # the robot talks again
    assert d.health().ok


def test_a_pose_older_than_stale_after_is_dropped_and_keeps_no_link(link):
    d = link.driver
    d.poll()
    link.offset = 2.0  # our clock runs 2 s ahead of the robot's stamps
    link.mono[0] += 0.3
    link.advance(0.1)
    assert d.poll() == [] and d.stale == 1
    link.mono[0] += 2.2  # link_timeout (2.5 s) since the last fresh pose: stale ones count not
    assert not d.health().ok


@pytest.mark.parametrize(
    "link", [Ros2Settings(namespace="/tb1", time_source="receipt")], indirect=True
)
def test_receipt_time_source_ignores_the_robots_clock(link):
    d = link.driver
    d.poll()
    link.offset = 100.0  # an unsynchronised robot clock
    link.advance(0.1)
    (m,) = d.poll()
    assert m.t == pytest.approx(link.robot.t + 100.0)


def test_a_bad_payload_is_counted_not_raised(link):
    d = link.driver
    d.poll()
    link.robot.pub.put(b"\x00\x01\x00\x00garbage", 0)
    link.robot.published += 1
    link.advance(0.1)
    assert len(d.poll()) == 1 and d.bad == 1 and d.health().ok


def test_a_pose_with_another_attachment_is_used_and_counted(link, caplog):
    """A robot on an rmw_zenoh older than the supported releases sends another attachment: its
    pose still counts, and the driver says once, as an error, what the robot runs."""
    d = link.driver
    d.poll()
    assert d.foreign_attachments == 0  # the stand-in's poses carry rmw_zenoh's 33 bytes
    payload = msgs.encode(
        "nav_msgs/msg/Odometry", msgs.pose_message("odometry", link.robot.t, 0.0, 0.0, 0.0)
    )
    for _ in range(2):
        link.robot.pub._pub.put(payload, attachment=b"\x00" * 40)  # not rmw_zenoh 0.2.4's
        link.robot.published += 1
    wait_for(lambda: d.samples_seen() >= link.robot.published, 5, "the poses")
    assert len(d.poll()) == 2 and d.foreign_attachments == 2
    said = [r for r in caplog.records if "40-byte attachment" in r.getMessage()]
    assert len(said) == 1 and "jazzy 0.2.4" in said[0].getMessage()


def test_a_pose_from_rosbags_with_covariance_gives_sigma(link):
    d = link.driver
    d.poll()
    payload = msgs.encode(
        "nav_msgs/msg/Odometry",
        msgs.pose_message("odometry", link.robot.t, 0.0, 0.0, 0.0, var_xy=0.0025, var_yaw=0.0009),
    )
    link.robot.pub.put(payload, 0)
    link.robot.published += 1
    wait_for(lambda: d.samples_seen() >= link.robot.published, 5, "the pose")
    (m,) = d.poll()
    assert (m.sigma_xy, m.sigma_theta) == pytest.approx((0.05, 0.03))
    link.advance(0.1)  # the stand-in's own poses carry no covariance: the configured sigma
    (m,) = d.poll()
    assert (m.sigma_xy, m.sigma_theta) == (link.settings.sigma_xy, link.settings.sigma_theta)


def test_no_router_at_the_endpoint_is_a_connect_timeout():
    """Nothing listens at ``connect``: ConnectTimeout naming the endpoint (a DriverError the
    agent reports, exit 1), not zenoh's own error; nothing left open."""
    from drivers.base import ConnectTimeout

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    d = Ros2Driver("r1", CAPS, Ros2Settings(connect=(endpoint,)), stale_after=0.5)
    with pytest.raises(ConnectTimeout, match=endpoint):
        d.connect(timeout=0.5)
    assert d._session is None
