"""The recorder of a run, daemon or ``fleet record``, set up from the config in one place:
the config metadata first, the Foxglove scene channels (``log.scene_hz``), segments
(``log.split_s``), sim-time stamps in a dry run, and the live view (``--viz``)."""

from __future__ import annotations

import logging
import sys
import threading
from collections.abc import Callable
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


class TwoPathTap:
    """The daemon recorder's tap when the e-stop has a second path (``zenoh.estop_listen``): an
    e-stop that comes by both paths is recorded once, from the path it came by first; one that
    comes only by the second (the hub hung) is recorded too. A repeat on one path is recorded
    as it comes; other keys pass through."""

    KEEP = 256  # e-stop payloads remembered (the newest)

    def __init__(self, tap: Callable[[str, bytes, float], None], estop_key: str) -> None:
        self.tap = tap
        self.key = estop_key
        self._seen: dict[bytes, str] = {}
        self._lock = threading.Lock()

    def path(self, name: str) -> Callable[[str, bytes, float], None]:
        """The tap of the path ``name``."""
        return lambda key, payload, t: self._on(name, key, payload, t)

    def _on(self, name: str, key: str, payload: bytes, t: float) -> None:
        if key == self.key:
            with self._lock:
                first = self._seen.setdefault(payload, name)
                if len(self._seen) > self.KEEP:
                    del self._seen[next(iter(self._seen))]
            if first != name:
                return  # the other path brought it first
        self.tap(key, payload, t)


def record_paths(bus: Any, second: Any, recorder: McapRecorder, skip: tuple[str, ...]) -> None:
    """The daemon's recorder taps: every logged topic of the hub's session but ``skip`` (the
    poses, read from the loop's rings) and, with a second path, the e-stops that come by it."""
    tap = TwoPathTap(recorder.on_sample, bus.key("estop"))
    bus.subscribe_raw_topics(tap.path("hub"), limit=True, skip=skip)
    if second is not None:
        second.subscribe_raw(second.key("estop"), tap.path("second"), limit=True)
