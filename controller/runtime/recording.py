"""The recorder of a run, daemon or ``fleet record``, set up from the config in one place:
the config metadata first, the Foxglove scene channels (``log.scene_hz``), segments
(``log.split_s``), sim-time stamps in a dry run, and the live view (``--viz``)."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

from controller.config import FleetConfig
from controller.io.recorder import SIM_EPOCH, McapRecorder, config_metadata
from controller.scene.builder import SceneBuilder

log = logging.getLogger(__name__)


def open_recorder(
    cfg: FleetConfig,
    out: Path,
    mode: str,
    *,
    sim_time: bool = False,
    viz: bool = False,
    who: str = "fleet",
) -> McapRecorder:
    """A recorder writing ``out`` (a folder of segments when ``log.split_s`` > 0).

    ``sim_time``: a dry run, stamped with sim time on ``SIM_EPOCH``; else the wall clock.
    ``viz``: serve every message live on 127.0.0.1:``viz.port`` (the URL goes to stderr).
    """
    epoch = SIM_EPOCH if sim_time else None
    scene = SceneBuilder(cfg, time_offset=epoch or 0.0) if cfg.log.scene_hz > 0 else None
    taps = []
    if viz:
        from controller.io.liveview import LiveView

        view = LiveView(cfg.viz.port, cfg.viz.queue, name=f"fleet {cfg.fleet.name}")
        taps.append(view)
        print(
            f"{who}: live view on {view.url} (Foxglove: Open connection → Foxglove WebSocket)",
            file=sys.stderr,
        )
    rec = McapRecorder(
        out,
        cfg.fleet.name,
        cfg.log.flush_interval,
        sim_epoch=epoch,
        split_s=cfg.log.split_s,
        scene=scene,
        taps=taps,
    )
    rec.metadata("fleet.config", config_metadata(cfg, mode))
    return rec


def record_ros2(bus: Any, cfg: FleetConfig, recorder: McapRecorder) -> list[str]:
    """Record the config's ROS 2 robots' own topics too (their ``cmd_vel`` and pose source,
    on rmw_zenoh's keys) as ROS 2 messages (``ros2msg``/``cdr``) under their ROS topic names.
    They arrive when the bus reaches the robots' zenoh network (the same router, or the hub
    connected to rmw_zenohd). Returns the keys subscribed."""
    from controller.runtime.wiring import ros2_settings
    from drivers.ros2.msgs import CMD_TYPES, POSE_TYPES, msg_definition

    subscribed = []
    for r in cfg.robots:
        if r.driver != "ros2":
            continue
        s = ros2_settings(r)
        for topic, type_name, key in (
            (s.cmd_fq(), CMD_TYPES[s.cmd_type], s.cmd_key()),
            (s.pose_fq(), POSE_TYPES[s.pose_type], s.pose_key()),
        ):
            recorder.native_channel(key, topic, type_name, msg_definition(type_name))
            bus.subscribe_raw(key, recorder.on_native)
            subscribed.append(key)
    return subscribed
