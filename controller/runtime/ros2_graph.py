"""The fleet shown to a ROS 2 graph (``[ros2_graph]``): the lab daemon publishes, on rmw_zenoh's
keys and with its liveliness tokens, what a lab's ROS 2 tools read without a bridge:

- ``/tf`` (``tf2_msgs/msg/TFMessage``): ``frame_id`` (the world, ``map`` by REP 105) to
  ``<robot id>/base_link`` for every robot with an estimate, and to ``object`` once it is known;
- ``<namespace>/<robot id>/pose`` and ``<namespace>/object/pose``
  (``geometry_msgs/msg/PoseStamped`` in ``frame_id``): the Kalman estimates the controller plans
  with;
- ``<namespace>/phase`` (``std_msgs/msg/String``): the job's phase, when it changes and every
  second (the topic is volatile: a tool that joins late has it within a second).

At ``ros2_graph.rate_hz``, stamped with the tick's time. The node, its publishers and the data
keys are :mod:`drivers.ros2` (the ROS 2 driver's own, checked against peers written outside
this repository), so ``ros2 topic list`` / ``echo``, RViz and rosbag2 see them as any node's.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from controller.config import FleetConfig
from controller.runtime.node_inputs import known
from drivers.ros2 import keys, msgs
from drivers.ros2.node import RmwNode, open_session

log = logging.getLogger(__name__)

TF = "tf2_msgs/msg/TFMessage"
POSE = "geometry_msgs/msg/PoseStamped"
STRING = "std_msgs/msg/String"
PHASE_EVERY = 1.0  # s: the phase again though unchanged (volatile topic, late joiners)


def _transform(t: float, parent: str, child: str, x: float, y: float, yaw: float) -> dict:
    return {
        "header": {"stamp": msgs.stamp(t), "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": float(x), "y": float(y), "z": 0.0},
            "rotation": msgs.yaw_quaternion(float(yaw)),
        },
    }


def graph_messages(
    t: float,
    frame_id: str,
    ids: list[str],
    poses: np.ndarray,
    known_robots: np.ndarray,
    object_pose: tuple[float, float, float] | None,
) -> tuple[dict, dict[str, dict]]:
    """The ``/tf`` message and the pose messages (by robot id, ``object``) at ``t`` for the
    robots ``known_robots`` (N,) bool at ``poses`` (N, 3) and the object (None: unknown)."""
    tf, out = [], {}
    for i, rid in enumerate(ids):
        if not known_robots[i]:
            continue
        x, y, yaw = (float(v) for v in poses[i])
        tf.append(_transform(t, frame_id, f"{rid}/base_link", x, y, yaw))
        out[rid] = msgs.pose_message("pose_stamped", t, x, y, yaw, frame_id=frame_id)
    if object_pose is not None:
        x, y, yaw = object_pose
        tf.append(_transform(t, frame_id, "object", x, y, yaw))
        out["object"] = msgs.pose_message("pose_stamped", t, x, y, yaw, frame_id=frame_id)
    return {"transforms": tf}, out


class Ros2Graph:
    """The daemon's node on the ROS graph; ``publish`` once per tick (it keeps its own rate)."""

    def __init__(self, cfg: FleetConfig) -> None:
        g = cfg.ros2_graph
        self.cfg = cfg
        self.period = 1.0 / g.rate_hz
        self.frame_id = g.frame_id
        self.ids = list(cfg.robot_ids)
        self.session = open_session(g.connect, mode=g.mode)
        self.node = RmwNode(self.session, g.domain_id, g.namespace, g.node_name)
        ns = g.namespace
        self.tf = self.node.publisher("/tf", TF)
        self.poses = {
            name: self.node.publisher(keys.qualify(ns, f"{name}/pose"), POSE)
            for name in [*self.ids, "object"]
        }
        self.phase = self.node.publisher(keys.qualify(ns, "phase"), STRING)
        self._next = -math.inf
        self._phase: tuple[str, float] | None = None
        self.published = 0

    def publish(self, now: float, node: Any) -> bool:
        """The fleet as ``node`` (the ``ControllerNode``) estimates it at ``now``, if due."""
        if now < self._next:
            return False
        self._next = max(self._next + self.period, now)
        poses, _vels, stale = node.est.robot_arrays(now)
        obj = known(node.est.object_estimate(now))
        where = None if obj is None else (obj.x, obj.y, obj.theta)
        tf, pose_msgs = graph_messages(
            now, self.frame_id, self.ids, poses, node.present & ~stale, where
        )
        stamp_ns = int(now * 1e9)
        self.tf.put(msgs.encode(TF, tf), stamp_ns)
        for name, m in pose_msgs.items():
            self.poses[name].put(msgs.encode(POSE, m), stamp_ns)
        phase = str(node.phase)
        if self._phase is None or self._phase[0] != phase or now - self._phase[1] >= PHASE_EVERY:
            self.phase.put(msgs.encode(STRING, {"data": phase}), stamp_ns)
            self._phase = (phase, now)
        self.published += 1
        return True

    def close(self) -> None:
        self.node.close()
        try:
            self.session.close()
        except Exception:  # noqa: BLE001 - best effort on shutdown
            log.debug("ros2 graph session close failed", exc_info=True)


def publish_graph(graph: Ros2Graph | None, now: float, node: Any) -> None:
    """``graph.publish`` when there is a graph; a failure is logged, never stops the loop."""
    if graph is None:
        return
    try:
        graph.publish(now, node)
    except Exception:  # noqa: BLE001 - the ROS graph is a view: the job goes on without it
        log.exception("ros2_graph: publishing failed")


def open_ros2_graph(cfg: FleetConfig) -> Ros2Graph | None:
    """The daemon's ROS 2 graph node when ``ros2_graph.enabled``; None otherwise, or (logged:
    the job runs without it) when the router cannot be reached."""
    if not cfg.ros2_graph.enabled:
        return None
    try:
        graph = Ros2Graph(cfg)
    except Exception as exc:  # noqa: BLE001 - zenoh's errors: the job does not need the graph
        log.error(
            "ros2_graph: cannot join the ROS graph at %s (%s): the fleet is not shown there; "
            "is rmw_zenohd running?",
            list(cfg.ros2_graph.connect),
            str(exc).split(" at ")[0],
        )
        return None
    log.info(
        "ros2_graph: the fleet on ROS domain %d under %s (/tf, poses, phase) at %g Hz",
        cfg.ros2_graph.domain_id,
        cfg.ros2_graph.namespace,
        cfg.ros2_graph.rate_hz,
    )
    return graph
