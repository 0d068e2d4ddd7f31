"""The ROS 2 driver's pure parts against outside references: type hashes against the values
rosidl generates (as they appear in the keys of real rmw_zenoh robots), keys and liveliness
tokens against ones captured from a Jazzy graph, the attachment against zenoh's own
serializer, and our CDR against rosbags, a second, independent CDR implementation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rosbags.typesys import get_types_from_msg

from drivers.ros2 import keys, msgs
from tests.support.ros2_robot import TYPESTORE, rosbags_decode, rosbags_pose

# published: the RIHS01 hashes rosidl generates for Jazzy's common_interfaces
PUBLISHED_HASHES = {
    "geometry_msgs/msg/Twist": (
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    ),
    "geometry_msgs/msg/TwistStamped": (
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
    ),
    "nav_msgs/msg/Odometry": (
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    ),
    # what [ros2_graph] publishes: /tf (an unbounded sequence of a nested type) and the phase
    # (rmw_zenoh's README shows this key for demo_nodes_cpp's chatter)
    "tf2_msgs/msg/TFMessage": (
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
    ),
    "std_msgs/msg/String": (
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    ),
}
# liveliness tokens of `ros2 topic echo /cmd_vel` on a Jazzy graph (rmw_zenoh 0.2.x)
JAZZY_NODE = "@ros2_lv/0/943f9ebc32acd3e072bfda12ce8c7ed2/0/0/NN/%/%/_ros2cli_31"
JAZZY_SUB = (
    "@ros2_lv/0/943f9ebc32acd3e072bfda12ce8c7ed2/0/4/MS/%/%/_ros2cli_31/%cmd_vel/"
    "geometry_msgs::msg::dds_::TwistStamped_/"
    "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64/2::,1:,:,:,,"
)


@pytest.mark.parametrize("type_name", sorted(PUBLISHED_HASHES))
def test_type_hash_matches_the_published_value(type_name):
    assert msgs.type_hash(type_name) == PUBLISHED_HASHES[type_name]


def test_pose_stamped_hash_has_the_published_prefix():
    assert msgs.type_hash("geometry_msgs/msg/PoseStamped").startswith("RIHS01_10f3786d7d40fd2b")


def test_data_key_as_rmw_zenoh_builds_it():
    assert keys.topic_key(0, "/cmd_vel", "geometry_msgs/msg/Twist") == (
        "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/" + PUBLISHED_HASHES["geometry_msgs/msg/Twist"]
    )
    assert keys.topic_key(7, keys.qualify("/tb4_1", "odom"), "nav_msgs/msg/Odometry") == (
        "7/tb4_1/odom/nav_msgs::msg::dds_::Odometry_/" + PUBLISHED_HASHES["nav_msgs/msg/Odometry"]
    )
    assert keys.qualify("/tb4_1", "/cmd_vel") == "/cmd_vel"  # absolute stays
    assert keys.qualify("", "cmd_vel") == keys.qualify("/", "cmd_vel") == "/cmd_vel"


def test_liveliness_tokens_match_a_jazzy_graph():
    zid = "943f9ebc32acd3e072bfda12ce8c7ed2"
    assert keys.node_token(0, zid, 0, "/", "_ros2cli_31") == JAZZY_NODE
    sub = keys.entity_token(
        keys.SUBSCRIPTION, 0, zid, 0, 4, "/", "_ros2cli_31", "/cmd_vel",
        "geometry_msgs/msg/TwistStamped", qos="2::,1:,:,:,,",
    )  # fmt: skip
    assert sub == JAZZY_SUB
    parsed = keys.parse_token(JAZZY_SUB)
    assert parsed is not None
    assert (parsed["kind"], parsed["topic"], parsed["node"]) == ("MS", "/cmd_vel", "_ros2cli_31")
    assert keys.parse_token("fleet/lab/alive/robot/r1") is None


def test_namespaced_tokens_mangle_every_slash():
    t = keys.entity_token(
        keys.PUBLISHER, 3, "ab", 0, 1, "/lab/tb1", "drv", "/lab/tb1/cmd_vel",
        "geometry_msgs/msg/Twist",
    )  # fmt: skip
    parts = t.split("/")
    assert parts[:9] == ["@ros2_lv", "3", "ab", "0", "1", "MP", "%", "%lab%tb1", "drv"]
    assert parts[9] == "%lab%tb1%cmd_vel" and parts[12] == keys.DEFAULT_QOS


def test_attachment_is_zenohs_serialization_of_seq_time_gid():
    from zenoh.ext import Int64, z_serialize

    gid = bytes(range(16))
    ours = keys.attachment(42, 1_700_000_000_123_456_789, gid)
    theirs = z_serialize((Int64(42), Int64(1_700_000_000_123_456_789), gid)).to_bytes()
    assert ours == theirs and len(ours) == 33
    assert keys.parse_attachment(ours) == (42, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError):
        keys.parse_attachment(ours[:-1])
    with pytest.raises(ValueError):
        keys.attachment(1, 0, b"short")


def test_gid_is_16_bytes_and_differs_per_entity():
    assert len(keys.gid(JAZZY_SUB)) == 16
    assert keys.gid(JAZZY_SUB) != keys.gid(JAZZY_NODE)


# XXH3_128bits("") (seed 0) in xxHash's own sanity table (tests/sanity_test_vectors.h):
# { low64 0x6001C324468D497F, high64 0x99AA06D3014798D8 }. rmw_zenoh memcpy's low64 then
# high64 into the GID on a little-endian host: each word's bytes reversed, low word first.
EMPTY_GID = bytes.fromhex("7f498d4624c30160d8984701d306aa99")  # low64 LE, high64 LE


def test_gid_is_rmw_zenohs_xxh3_128_low_then_high_little_endian():
    """The GID of rmw_zenoh's ``Entity``: XXH3-128 of the liveliness key expression, low64 then
    high64, little endian. Checked against xxHash's published vector for the empty input
    (byte order worked out by hand above) and, for a real token, against xxhash's canonical
    digest (big-endian high64 || low64) split and reordered here, independently of keys.gid."""
    import xxhash

    assert keys.gid("") == EMPTY_GID
    canonical = xxhash.xxh3_128(JAZZY_SUB.encode()).hexdigest()  # high64 then low64, hex
    high, low = bytes.fromhex(canonical[:16]), bytes.fromhex(canonical[16:])
    assert keys.gid(JAZZY_SUB) == low[::-1] + high[::-1]
    import hashlib

    assert keys.gid(JAZZY_SUB) != hashlib.sha256(JAZZY_SUB.encode()).digest()[:16]


# --------------------------------------------------------------------------- CDR


def test_the_schema_text_is_valid_ros2msg():
    """rosbags parses our ros2msg text (the MCAP schema) into the types it knows itself."""
    for name in ("nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistStamped"):
        types = get_types_from_msg(msgs.msg_definition(name), name)
        assert name in types


@pytest.mark.parametrize("cmd_type", sorted(msgs.CMD_TYPES))
def test_our_twist_decodes_with_rosbags_rep103(cmd_type):
    """REP 103 body frame = our command's: vx → linear.x, vy → linear.y, wz → angular.z."""
    type_name = msgs.CMD_TYPES[cmd_type]
    payload = msgs.encode(type_name, msgs.twist_message(cmd_type, 0.3, -0.1, 0.7, 12.25, "base"))
    assert payload[:4] == b"\x00\x01\x00\x00"  # CDR little endian, as Fast CDR writes it
    m = rosbags_decode(type_name, payload)
    tw = m if cmd_type == "twist" else m.twist
    assert (tw.linear.x, tw.linear.y, tw.linear.z) == (0.3, -0.1, 0.0)
    assert (tw.angular.x, tw.angular.y, tw.angular.z) == (0.0, 0.0, 0.7)
    if cmd_type == "twist_stamped":
        assert (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) == (
            12, 250_000_000, "base",
        )  # fmt: skip


@pytest.mark.parametrize("pose_type", sorted(msgs.POSE_TYPES))
def test_our_pose_messages_decode_with_rosbags(pose_type):
    type_name = msgs.POSE_TYPES[pose_type]
    payload = msgs.encode(
        type_name, msgs.pose_message(pose_type, 5.5, 1.0, -2.0, 2.5, var_xy=0.04, var_yaw=0.01)
    )
    m = rosbags_decode(type_name, payload)
    pose = m.pose.pose if pose_type == "odometry" else m.pose
    assert (pose.position.x, pose.position.y) == (1.0, -2.0)
    q = pose.orientation
    assert math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z) == pytest.approx(2.5)
    if pose_type == "odometry":
        assert m.pose.covariance[0] == 0.04 and m.pose.covariance[35] == 0.01
        assert m.child_frame_id == "base_link"


@pytest.mark.parametrize("pose_type", sorted(msgs.POSE_TYPES))
def test_rosbags_poses_read_by_our_codec(pose_type):
    type_name = msgs.POSE_TYPES[pose_type]
    payload = rosbags_pose(type_name, 3.75, 1.5, 2.5, -3.0)
    p = msgs.read_pose(pose_type, msgs.decode(type_name, payload))
    assert (p.t, p.x, p.y, p.frame_id) == (3.75, 1.5, 2.5, "odom")
    assert p.yaw == pytest.approx(-3.0)


def test_a_bad_payload_is_a_value_error():
    with pytest.raises(ValueError, match="nav_msgs/msg/Odometry"):
        msgs.decode("nav_msgs/msg/Odometry", b"\x00\x01\x00\x00\x01")


def test_byte_identical_to_rosbags():
    """Same message, same bytes: the two implementations agree on alignment and padding."""
    T = TYPESTORE.types
    vec = T["geometry_msgs/msg/Vector3"]
    stamp = T["builtin_interfaces/msg/Time"](sec=12, nanosec=250_000_000)
    theirs = T["geometry_msgs/msg/TwistStamped"](
        header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="base"),
        twist=T["geometry_msgs/msg/Twist"](
            linear=vec(x=0.3, y=-0.1, z=0.0), angular=vec(x=0.0, y=0.0, z=0.7)
        ),
    )
    ours = msgs.twist_message("twist_stamped", 0.3, -0.1, 0.7, 12.25, "base")
    assert msgs.encode("geometry_msgs/msg/TwistStamped", ours) == bytes(
        TYPESTORE.serialize_cdr(theirs, "geometry_msgs/msg/TwistStamped")
    )
    odom = msgs.encode("nav_msgs/msg/Odometry", msgs.pose_message("odometry", 3.75, 1, 2, 0.5))
    assert odom == rosbags_pose("nav_msgs/msg/Odometry", 3.75, 1.0, 2.0, 0.5)


# --------------------------------------------------------------------------- frames (REP 105)


def test_odom_pose_placed_in_the_world():
    """The odom frame sits at (1, 2) turned 90°: 1 m forward in odom is 1 m north in ENU."""
    x, y, th = keys.odom_to_world(1.0, 0.0, 0.0, (1.0, 2.0, math.pi / 2))
    assert (x, y, th) == pytest.approx((1.0, 3.0, math.pi / 2))


angles = st.floats(-10, 10, allow_nan=False)
coords = st.floats(-50, 50, allow_nan=False)


@given(coords, coords, angles, coords, coords, angles)
def test_world_to_odom_inverts_odom_to_world(x, y, yaw, tx, ty, tyaw):
    w = keys.odom_to_world(x, y, yaw, (tx, ty, tyaw))
    back = keys.world_to_odom(*w, (tx, ty, tyaw))
    assert back[:2] == pytest.approx((x, y), abs=1e-9)
    assert math.remainder(back[2] - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert -math.pi <= w[2] <= math.pi


@given(angles)
def test_quaternion_yaw_round_trip(yaw):
    q = msgs.yaw_quaternion(yaw)
    obj = type("Q", (), q)
    assert math.remainder(msgs.quaternion_yaw(obj) - yaw, 2 * math.pi) == pytest.approx(
        0.0, abs=1e-9
    )
    assert np.isclose(sum(v * v for v in q.values()), 1.0)


def test_the_graph_messages_encode_as_rosbags_decodes_them():
    """/tf with two frames (an unbounded sequence of nested messages) and the phase, encoded by
    the driver's codec, decoded by rosbags (the independent one) to the same values."""
    from controller.runtime.ros2_graph import graph_messages

    poses = np.array([[1.0, 2.0, 0.5], [3.0, -1.0, -2.0]])
    tf, pose_msgs = graph_messages(12.25, "map", ["r1", "r2"], poses, np.array([True, True]),
                                   (4.0, 5.0, 1.0))  # fmt: skip
    got = rosbags_decode("tf2_msgs/msg/TFMessage", msgs.encode("tf2_msgs/msg/TFMessage", tf))
    assert [t.child_frame_id for t in got.transforms] == ["r1/base_link", "r2/base_link", "object"]
    t = got.transforms[1]
    assert (t.header.frame_id, t.header.stamp.sec, t.header.stamp.nanosec) == ("map", 12, 250000000)
    assert (t.transform.translation.x, t.transform.translation.y) == (3.0, -1.0)
    assert msgs.quaternion_yaw(t.transform.rotation) == pytest.approx(-2.0)
    stamped = "geometry_msgs/msg/PoseStamped"
    pose = rosbags_decode(stamped, msgs.encode(stamped, pose_msgs["object"]))
    assert (pose.pose.position.x, pose.pose.position.y) == (4.0, 5.0)
    text = rosbags_decode(
        "std_msgs/msg/String", msgs.encode("std_msgs/msg/String", {"data": "hold"})
    )
    assert text.data == "hold"
