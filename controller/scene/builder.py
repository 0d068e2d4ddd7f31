"""The Foxglove scene of a run, derived from the bus messages and the config (pure).

``SceneBuilder.ingest(key, obj)`` takes one decoded bus payload (a JSON object, as the recorder
parses it anyway) and returns the scene messages it makes due; ``flush()`` returns the last frame.
The recorder writes them beside the bus channels; the live view serves them over a WebSocket.

Channels (``SCENE_TOPICS``), all in the world frame ``world`` (ENU, metres):

- ``/tf`` (``foxglove.FrameTransforms``, every frame): ``world`` → ``robot/<id>`` (the filter's
  estimate), ``world`` → ``object`` (estimate) and, in a dry run, ``world`` → ``object/truth``;
- ``/scene/world`` (``foxglove.SceneUpdate``): walls, obstacles (extruded to their height), the
  goal footprint;
- ``/scene/robots``: one cylinder per robot (its radius), heading arrow and label, locked to its
  frame, coloured by role: grey a spare, the phase's colour for a capture robot, in transport
  the colour of its action (push, follow, slide, relocate, idle); faded when its estimate is
  stale, black when its link is lost;
- ``/scene/object``: the object extruded at its estimated pose, its true outline (dry run), and
  its path so far;
- ``/scene/plan``: capture points and push normals (object frame), the route and its subgoal
  footprints, re-arrangement targets, the transport's pushers with their contact forces as
  arrows (1 cm per newton) and the predicted object path;
- ``/scene/route`` (``foxglove.PosesInFrame``): the route's waypoints with headings;
- ``/log`` (``foxglove.Log``): phases, plans, arrest, failures, e-stops, lost links;
- ``/scene/stats`` (``fleet.SceneStats``, numbers to plot): phase, e-stop, smallest robot-robot
  gap, smallest robot-object gap, robot and object speeds, pushers and their total force, the
  object's lateral deviation from the route.

Frames are emitted at most ``rate_hz`` per second of the run's own clock, each once a tick is
complete (when a controller output of a later tick arrives); entities that did not change are
re-sent every ``static_every`` seconds so a player that seeks still finds them. Message times are
the run's clock plus ``time_offset`` (the sim epoch in a dry run, 0 in the lab).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from controller import geometry, wire
from controller.config import FleetConfig
from controller.events import (
    ArrestEvent,
    CaptureEvent,
    Event,
    FailureEvent,
    GenericEvent,
    LinkLostEvent,
    LinkRestoredEvent,
    PhaseEvent,
    RearrangeEvent,
    RouteEvent,
    TransportEvent,
    parse_event,
)
from controller.scene import primitives as P

SCHEMA_DIR = Path(__file__).resolve().parent / "schemas"
WORLD = "world"
SCENE_TOPICS: dict[str, str] = {
    "/tf": "foxglove.FrameTransforms",
    "/scene/world": "foxglove.SceneUpdate",
    "/scene/robots": "foxglove.SceneUpdate",
    "/scene/object": "foxglove.SceneUpdate",
    "/scene/plan": "foxglove.SceneUpdate",
    "/scene/route": "foxglove.PosesInFrame",
    "/log": "foxglove.Log",
    "/scene/stats": "fleet.SceneStats",
}
FORCE_SCALE = 0.01  # m of arrow per newton
OBJECT_HEIGHT = 0.25  # m (the config has no height for the object)
ROBOT_HEIGHT = 0.2  # m
PATH_POINTS = 400  # object path: at most this many points (decimated)

GREY: P.Color = (0.62, 0.62, 0.62, 1.0)
PHASE_COLORS: dict[str, P.Color] = {
    "init": GREY,
    "approach": (0.20, 0.45, 0.90, 1.0),
    "close_in": (0.10, 0.70, 0.85, 1.0),
    "hold": (0.95, 0.65, 0.10, 1.0),
    "arrested": (0.20, 0.75, 0.30, 1.0),
    "done": (0.20, 0.75, 0.30, 1.0),
    "route": (0.55, 0.35, 0.85, 1.0),
    "rearrange": (0.85, 0.45, 0.75, 1.0),
    "transport": (0.95, 0.45, 0.15, 1.0),
    "failed": (0.85, 0.10, 0.10, 1.0),
}
ACTION_COLORS: dict[str, P.Color] = {
    "push": (0.90, 0.25, 0.10, 1.0),
    "follow": (0.20, 0.70, 0.30, 1.0),
    "slide_left": (0.60, 0.30, 0.85, 1.0),
    "slide_right": (0.60, 0.30, 0.85, 1.0),
    "relocate": (0.95, 0.80, 0.10, 1.0),
    "idle": GREY,
}
LOST: P.Color = (0.05, 0.05, 0.05, 1.0)
OBSTACLE: P.Color = (0.45, 0.45, 0.50, 1.0)
WALL: P.Color = (0.35, 0.35, 0.40, 1.0)
OBJECT: P.Color = (0.80, 0.55, 0.30, 0.9)
TRUTH: P.Color = (0.10, 0.10, 0.10, 1.0)
GOAL: P.Color = (0.20, 0.75, 0.30, 1.0)
CAPTURE: P.Color = (0.10, 0.80, 0.90, 1.0)
ROUTE: P.Color = (0.55, 0.35, 0.85, 1.0)
LEVELS = {"failure": P.LOG_ERROR, "escape": P.LOG_WARNING, "contact_lost": P.LOG_WARNING}
LEVELS |= {"safety_stop": P.LOG_WARNING, "transport": P.LOG_DEBUG}

STATS_SCHEMA: dict[str, Any] = {
    "title": "fleet.SceneStats",
    "description": "Figures of one scene frame (SI units; null: not known yet)",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "run time (s): sim time in a dry run"},
        "phase": {"type": "string"},
        "phase_index": {"type": "integer", "description": "position of the phase in the job"},
        "estop": {"type": "boolean"},
        "robots": {"type": "integer", "description": "robots with an estimate"},
        "stale_robots": {"type": "integer"},
        "min_clearance_m": {"type": ["number", "null"], "description": "robot-robot gap"},
        "min_object_gap_m": {"type": ["number", "null"], "description": "robot-object gap"},
        "max_speed_mps": {"type": ["number", "null"]},
        "mean_speed_mps": {"type": ["number", "null"]},
        "object_speed_mps": {"type": ["number", "null"]},
        "pushers": {"type": "integer"},
        "push_force_n": {"type": "number"},
        "lateral_deviation_m": {"type": ["number", "null"], "description": "from the route"},
    },
    "required": [
        "t",
        "phase",
        "phase_index",
        "estop",
        "robots",
        "stale_robots",
        "min_clearance_m",
        "min_object_gap_m",
        "max_speed_mps",
        "mean_speed_mps",
        "object_speed_mps",
        "pushers",
        "push_force_n",
        "lateral_deviation_m",
    ],
    "additionalProperties": False,
}
PHASE_ORDER = tuple(PHASE_COLORS)
# messages stamped with the controller's (or the sim's) tick time: a later one starts a new tick
FRAME_TRIGGERS = ("robot_cmd", "plan", "robot_state", "object_state", "truth_robot", "truth_object")
# the plan events the scene draws, by the attribute that keeps the latest of each
PLAN_TYPES: dict[str, type[Event]] = {
    "capture": CaptureEvent,
    "route": RouteEvent,
    "rearrange": RearrangeEvent,
    "transport": TransportEvent,
}
PLAN_KINDS = tuple(PLAN_TYPES)
SHOWN_IN = {
    "capture": ("approach", "close_in", "hold", "arrested", "done"),
    "rearrange": ("rearrange",),
    "transport": ("transport",),
}


@cache
def schema(name: str) -> dict[str, Any]:
    """The JSON Schema of a scene channel's message type (Foxglove's published ones, vendored
    in ``schemas/``, or ours)."""
    if name == STATS_SCHEMA["title"]:
        return STATS_SCHEMA
    stem = name.removeprefix("foxglove.")
    return json.loads((SCHEMA_DIR / f"{stem}.json").read_text())


def schema_bytes(name: str) -> bytes:
    return json.dumps(schema(name), separators=(",", ":")).encode()


@dataclass(frozen=True)
class SceneMessage:
    """One scene message: channel, schema name, JSON-ready payload, run time ``t`` (s, without
    the offset) and absolute time ``stamp`` (s, with it)."""

    topic: str
    schema: str
    data: dict[str, Any]
    t: float
    stamp: float

    def payload(self) -> bytes:
        return json.dumps(self.data, separators=(",", ":"), allow_nan=False).encode()


@dataclass
class _Robot:
    pose: np.ndarray | None = None
    vel: np.ndarray = field(default_factory=lambda: np.zeros(2))
    stale: bool = False
    lost: bool = False
    shown: tuple | None = None  # (colour, label) last sent


class SceneBuilder:
    """Turns a run's bus messages into Foxglove scene messages (see the module doc)."""

    def __init__(
        self,
        cfg: FleetConfig,
        time_offset: float = 0.0,
        rate_hz: float | None = None,
        static_every: float = 2.0,
    ) -> None:
        self.cfg = cfg
        self.fleet = cfg.fleet.name
        self.offset = time_offset
        rate = cfg.log.scene_hz if rate_hz is None else rate_hz
        self.period = 1.0 / rate if rate > 0 else math.inf
        self.static_every = static_every
        self.poly = geometry.ensure_ccw(cfg.object_polygon())
        self.radius = {r.id: r.radius for r in cfg.robots}
        self.robots = {r.id: _Robot() for r in cfg.robots}
        self.object: np.ndarray | None = None
        self.object_vel = np.zeros(2)
        self.truth: np.ndarray | None = None
        self.path: list[tuple[float, float]] = []
        self.phase = "init"
        self.estop = False
        self.capture: CaptureEvent | None = None
        self.route: RouteEvent | None = None
        self.rearrange: RearrangeEvent | None = None
        self.transport: TransportEvent | None = None
        self.frame_t: float | None = None
        self._next_frame = -math.inf
        self._next_static = -math.inf
        self._dirty: set[str] = set()  # plan entities to re-send: capture, route, ...
        self._object_shown = (False, False)  # (estimate, truth) entities sent
        self._keys: dict[str, wire.KeyParts | None] = {}
        self._handlers = {
            name: getattr(self, f"_on_{name}")
            for name in wire.TOPICS
            if hasattr(self, f"_on_{name}")
        }

    # -- input
    def ingest(self, key: str, obj: Any) -> list[SceneMessage]:
        """One bus payload (decoded JSON) on ``key``: the scene messages now due."""
        if key in self._keys:
            parsed = self._keys[key]
        else:
            parsed = self._keys[key] = wire.parse_key(key, self.fleet)
        if parsed is None or not isinstance(obj, dict) or self.period == math.inf:
            return []
        name = parsed.topic.name
        t = _number(obj.get("t"))
        if t is None:
            return []
        out: list[SceneMessage] = []
        if name in FRAME_TRIGGERS:
            if self.frame_t is None or t > self.frame_t + 1e-9:
                if self.frame_t is not None:
                    out += self._frame(self.frame_t)
                self.frame_t = t
        handler = self._handlers.get(name)
        if handler is not None:
            out += handler(self._when(t), parsed, obj) or []
        return out

    def flush(self) -> list[SceneMessage]:
        """The last frame (at the end of a run or a segment)."""
        if self.frame_t is None:
            return []
        self._next_frame = -math.inf
        return self._frame(self.frame_t)

    def resend(self) -> None:
        """Send every entity again with the next frame (a new log segment starts)."""
        self._next_static = -math.inf

    def _when(self, t: float) -> float:
        """A message's time on the run's clock; a stamp from another clock (an operator's e-stop
        stamped with the wall clock in a dry run) is taken as the current frame's time."""
        if self.frame_t is not None and abs(t - self.frame_t) > 60.0:
            return self.frame_t
        return t

    def _on_robot_state(self, t: float, key: wire.KeyParts, m: dict) -> None:
        r = self.robots.get(key.id)
        if r is not None:
            r.pose = np.array([m.get("x", 0.0), m.get("y", 0.0), m.get("theta", 0.0)], float)
            r.vel = np.array([m.get("vx", 0.0), m.get("vy", 0.0)], float)
            r.stale = bool(m.get("stale", False))

    def _on_object_state(self, t: float, key: wire.KeyParts, m: dict) -> None:
        self.object = np.array([m.get("x", 0.0), m.get("y", 0.0), m.get("theta", 0.0)], float)
        self.object_vel = np.array([m.get("vx", 0.0), m.get("vy", 0.0)], float)
        if not self.path or math.dist(self.path[-1], self.object[:2]) > 0.02:
            self.path.append((float(self.object[0]), float(self.object[1])))
            if len(self.path) > PATH_POINTS:
                self.path = self.path[::2]

    def _on_truth_object(self, t: float, key: wire.KeyParts, m: dict) -> None:
        self.truth = np.array([m.get("x", 0.0), m.get("y", 0.0), m.get("theta", 0.0)], float)

    def _on_estop(self, t: float, key: wire.KeyParts, m: dict) -> list[SceneMessage]:
        engaged = bool(m.get("engaged"))
        if engaged == self.estop:
            return []
        self.estop = engaged
        who = m.get("source") or "?"
        words = f"E-STOP engaged by {who}" if engaged else f"e-stop released by {who}"
        if m.get("reason"):
            words += f": {m['reason']}"
        return [self._log(t, P.LOG_ERROR if engaged else P.LOG_INFO, words)]

    def _on_robot_event(self, t: float, key: wire.KeyParts, m: dict) -> list[SceneMessage]:
        kind = str(m.get("kind", ""))
        ev = parse_event(kind, m.get("data"))
        lost = isinstance(ev, LinkLostEvent) or kind == LinkLostEvent.KIND  # even misshapen
        if lost and key.id in self.robots:
            self.robots[key.id].lost = True
        level = P.LOG_ERROR if lost else P.LOG_INFO
        link = isinstance(ev, LinkLostEvent | LinkRestoredEvent)
        detail = ev.detail if link else ev.to_dict().get("detail", "")  # another kind: as sent
        return [self._log(t, level, f"robot {key.id}: {kind} {detail}".strip(), key.id)]

    def _on_plan(self, t: float, key: wire.KeyParts, m: dict) -> list[SceneMessage]:
        """A plan event, typed (one of a kind the scene does not know, or that does not fit
        its kind, is only logged: the plan drawn stays the last one that fitted)."""
        ev = parse_event(key.what, m.get("data"))
        phase = str(m.get("phase") or self.phase)
        if isinstance(ev, PhaseEvent):
            phase = str(ev.phase)
        elif isinstance(ev, GenericEvent) and ev.kind == "phase":
            phase = str(ev.data.get("phase", phase))  # a phase word this version lacks
        if phase != self.phase:
            self._dirty.update(PLAN_KINDS)  # what is shown depends on the phase
        self.phase = phase
        if isinstance(ev, tuple(PLAN_TYPES.values())):
            setattr(self, ev.kind, ev)
            self._dirty.add(ev.kind)
        return [self._log(t, LEVELS.get(ev.kind, P.LOG_INFO), describe(ev, phase))]

    def _log(self, t: float, level: int, words: str, name: str = "controller") -> SceneMessage:
        st = t + self.offset
        return SceneMessage("/log", "foxglove.Log", P.log_entry(st, level, words, name), t, st)

    # -- output
    def _msg(self, topic: str, data: dict[str, Any], t: float) -> SceneMessage:
        return SceneMessage(topic, SCENE_TOPICS[topic], data, t, t + self.offset)

    def _frame(self, t: float) -> list[SceneMessage]:
        if t < self._next_frame - 1e-9:
            return []
        self._next_frame = t + self.period
        everything = t >= self._next_static - 1e-9
        if everything:
            self._next_static = t + self.static_every
            self._dirty.update(PLAN_KINDS)
        st = t + self.offset
        out = [self._msg("/tf", self._transforms(st), t)]
        if everything:
            out.append(self._msg("/scene/world", P.scene_update(self._world(st)), t))
        robots = self._robot_entities(st, everything)
        if robots:
            out.append(self._msg("/scene/robots", P.scene_update(robots), t))
        shown = (self.object is not None, self.truth is not None)
        if everything or shown != self._object_shown:  # it moves by /tf: re-sent now and then
            self._object_shown = shown
            out.append(self._msg("/scene/object", P.scene_update(self._object_entities(st)), t))
        plan = self._plan_entities(st)
        if plan:
            out.append(self._msg("/scene/plan", P.scene_update(plan), t))
        if self.route is not None and ("route" in self._dirty or everything):
            out.append(self._msg("/scene/route", self._route_poses(st), t))
        self._dirty.clear()
        out.append(self._msg("/scene/stats", self.stats(t), t))
        return out

    def _transforms(self, st: float) -> dict[str, Any]:
        tfs = [
            P.transform(st, WORLD, f"robot/{rid}", *r.pose)
            for rid, r in self.robots.items()
            if r.pose is not None
        ]
        if self.object is not None:
            tfs.append(P.transform(st, WORLD, "object", *self.object))
        if self.truth is not None:
            tfs.append(P.transform(st, WORLD, "object/truth", *self.truth))
        return {"transforms": tfs}

    def _world(self, st: float) -> list[dict[str, Any]]:
        cfg = self.cfg
        (x0, y0), (x1, y1) = cfg.bounds_array()
        room = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        walls: list[dict] = []
        if cfg.world.walls:
            th, h = 0.05, 0.3
            cx, cy, w, d = (x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0
            for x, y, sx, sy in (
                (cx, y0 - th / 2, w + 2 * th, th),
                (cx, y1 + th / 2, w + 2 * th, th),
                (x0 - th / 2, cy, th, d),
                (x1 + th / 2, cy, th, d),
            ):
                walls.append(P.cube(x, y, h / 2, (sx, sy, h), 0.0, WALL))
        ents = [
            P.entity("room", st, WORLD, cubes=walls, lines=[P.line(P.LINE_LOOP, room, WALL, 0.005)])
        ]
        for k, o in enumerate(cfg.obstacles):
            poly = np.asarray(o.polygon, float)
            ents.append(
                P.entity(f"obstacle/{k}", st, WORLD, triangles=[P.prism(poly, o.height, OBSTACLE)])
            )
        if cfg.object.goal is not None:
            goal = geometry.transform(self.poly, cfg.object.goal)
            c = geometry.centroid(goal)
            ents.append(
                P.entity(
                    "goal",
                    st,
                    WORLD,
                    lines=[P.line(P.LINE_LOOP, goal, GOAL, 0.01, 0.03)],
                    texts=[P.text(c[0], c[1], 0.3, "goal", GOAL)],
                )
            )
        return ents

    def _role(self, rid: str, actions: dict[str, str]) -> tuple[P.Color, str]:
        r = self.robots[rid]
        if r.lost:
            return LOST, f"{rid} LINK LOST"
        action = actions.get(rid)
        if action is not None and self.phase == "transport":
            col, label = ACTION_COLORS.get(action, GREY), f"{rid} {action}"
        elif self.capture is not None and rid in self.capture.robots:
            col, label = PHASE_COLORS.get(self.phase, GREY), rid
        else:
            col, label = GREY, rid
        if r.stale:
            col, label = (*col[:3], 0.35), f"{label} (stale)"
        return col, label

    def _actions(self) -> dict[str, str]:
        if self.transport is None:
            return {}
        ids = _transport_ids(self.transport, self.capture)
        return dict(zip(ids, _list(self.transport.plan.get("first_actions")), strict=False))

    def _robot_entities(self, st: float, everything: bool) -> list[dict[str, Any]]:
        out = []
        actions = self._actions()
        for rid, r in self.robots.items():
            if r.pose is None:
                continue
            look = self._role(rid, actions)
            if not everything and look == r.shown:
                continue
            r.shown = look
            col, label = look
            rad = self.radius[rid]
            out.append(
                P.entity(
                    f"robot/{rid}",
                    st,
                    f"robot/{rid}",
                    frame_locked=True,
                    metadata={"robot": rid, "phase": self.phase},
                    cylinders=[P.cylinder(0, 0, ROBOT_HEIGHT / 2, 2 * rad, ROBOT_HEIGHT, col)],
                    arrows=[P.arrow(0, 0, ROBOT_HEIGHT + 0.01, 0.0, 1.3 * rad, LOST, 0.02)],
                    texts=[P.text(0, 0, ROBOT_HEIGHT + 0.15, label, col)],
                )
            )
        return out

    def _object_entities(self, st: float) -> list[dict[str, Any]]:
        out = []
        if self.object is not None:
            out.append(
                P.entity(
                    "object",
                    st,
                    "object",
                    frame_locked=True,
                    triangles=[P.prism(self.poly, OBJECT_HEIGHT, OBJECT)],
                    lines=[P.line(P.LINE_LOOP, self.poly, TRUTH, OBJECT_HEIGHT, 0.01)],
                )
            )
        if self.truth is not None:
            out.append(
                P.entity(
                    "object/truth",
                    st,
                    "object/truth",
                    frame_locked=True,
                    lines=[P.line(P.LINE_LOOP, self.poly, TRUTH, 0.02, 0.02)],
                )
            )
        if len(self.path) > 1:
            path = np.asarray(self.path)
            out.append(
                P.entity("object/path", st, WORLD, lines=[P.line(P.LINE_STRIP, path, OBJECT, 0.01)])
            )
        return out

    def _plan_entities(self, st: float) -> list[dict[str, Any]]:
        """The plan's entities that changed (emptied when their phase is over)."""
        out = []
        for kind in PLAN_KINDS:
            ev = getattr(self, kind)
            if kind not in self._dirty or ev is None:
                continue
            if kind in SHOWN_IN and self.phase not in SHOWN_IN[kind]:
                ev = None  # its phase is over: the entities emptied
            out += getattr(self, f"_{kind}_entities")(st, ev)
        return out

    def _rearrange_entities(self, st: float, ev: RearrangeEvent | None) -> list[dict[str, Any]]:
        pts = [
            P.sphere(p[0], p[1], 0.05, 0.08, ACTION_COLORS["relocate"])
            for p in (ev.contacts if ev is not None else {}).values()
            if _is_point(p)
        ]
        return [P.entity("rearrange", st, "object", frame_locked=True, spheres=pts)]

    def _capture_entities(self, st: float, cap: CaptureEvent | None) -> list[dict[str, Any]]:
        spheres, arrows = [], []
        points, normals = (cap.points, cap.normals) if cap is not None else ([], [])
        for p, n in zip(points, normals, strict=False):
            if not (_is_point(p) and _is_point(n)):
                continue
            spheres.append(P.sphere(p[0], p[1], 0.05, 0.07, CAPTURE))
            start = np.asarray(p, float) + 0.3 * np.asarray(n, float)
            yaw = math.atan2(-n[1], -n[0])  # the push: into the object
            arrows.append(P.arrow(start[0], start[1], 0.05, yaw, 0.28, CAPTURE, 0.015))
        return [
            P.entity("capture", st, "object", frame_locked=True, spheres=spheres, arrows=arrows)
        ]

    def _route_entities(self, st: float, route: RouteEvent | None) -> list[dict[str, Any]]:
        wp = _points(route.waypoints if route is not None else None, 3)
        lines = []
        if len(wp) > 1:
            lines.append(P.line(P.LINE_STRIP, wp[:, :2], ROUTE, 0.02, 0.04))
        for sg in _points(route.subgoals if route is not None else None, 3):
            lines.append(P.line(P.LINE_LOOP, geometry.transform(self.poly, sg), ROUTE, 0.02, 0.01))
        return [P.entity("route", st, WORLD, lines=lines)]

    def _route_poses(self, st: float) -> dict[str, Any]:
        wp = _points(self.route.waypoints if self.route else None, 3)
        return {
            "timestamp": P.stamp(st),
            "frame_id": WORLD,
            "poses": [P.pose(p[0], p[1], 0.02, p[2]) for p in wp],
        }

    def _transport_entities(self, st: float, tr: TransportEvent | None) -> list[dict[str, Any]]:
        plan = tr.plan if tr is not None else {}
        actions = _list(plan.get("first_actions"))
        forces = _list((tr.forces or [[]])[0] if tr is not None else None)
        arrows = []
        for k, p in enumerate(_list(plan.get("contact_points"))):
            f = _number(forces[k]) if k < len(forces) else None
            if not _is_point(p) or not f or f <= 0:
                continue
            inward = _inward_normal(self.poly, np.asarray(p, float))
            length = float(np.clip(FORCE_SCALE * f, 0.05, 1.5))
            start = np.asarray(p, float) - (length + 0.02) * inward
            col = ACTION_COLORS.get(actions[k] if k < len(actions) else "", GREY)
            yaw = math.atan2(inward[1], inward[0])
            arrows.append(P.arrow(start[0], start[1], 0.12, yaw, length, col, 0.025))
        out = [P.entity("transport/forces", st, "object", frame_locked=True, arrows=arrows)]
        pred = _points(plan.get("object_poses"), 3)
        lines = []
        if len(pred) > 1:
            lines.append(P.line(P.LINE_STRIP, self._centroids(pred), ACTION_COLORS["push"], 0.03))
        out.append(P.entity("transport/prediction", st, WORLD, lines=lines))
        return out

    def stats(self, t: float) -> dict[str, Any]:
        """The numbers of the ``/scene/stats`` channel at run time ``t``."""
        ids = [rid for rid, r in self.robots.items() if r.pose is not None]
        xy = np.array([self.robots[r].pose[:2] for r in ids]).reshape(-1, 2)
        radii = np.array([self.radius[r] for r in ids])
        speeds = np.array([float(np.hypot(*self.robots[r].vel)) for r in ids])
        gap = geometry.min_disc_gap(xy, radii) if len(ids) > 1 else math.inf
        obj_gap = None
        if self.object is not None and ids:
            local = geometry.inverse_transform(xy, self.object)
            obj_gap = float(np.min(geometry.polygon_signed_distance(local, self.poly) - radii))
        tr = self.transport if self.phase == "transport" else None
        forces = [f for f in _list((tr.forces or [[]])[0] if tr else None) if _number(f)]
        return {
            "t": float(t),
            "phase": self.phase,
            "phase_index": PHASE_ORDER.index(self.phase) if self.phase in PHASE_ORDER else -1,
            "estop": self.estop,
            "robots": len(ids),
            "stale_robots": sum(self.robots[r].stale for r in ids),
            "min_clearance_m": None if math.isinf(gap) else round(float(gap), 5),
            "min_object_gap_m": None if obj_gap is None else round(obj_gap, 5),
            "max_speed_mps": round(float(speeds.max()), 5) if len(ids) else None,
            "mean_speed_mps": round(float(speeds.mean()), 5) if len(ids) else None,
            "object_speed_mps": None
            if self.object is None
            else round(float(np.hypot(*self.object_vel)), 5),
            "pushers": sum(1 for f in forces if f > 0),
            "push_force_n": round(float(sum(f for f in forces if f > 0)), 4),
            "lateral_deviation_m": self._deviation(),
        }

    def _deviation(self) -> float | None:
        if self.object is None or self.route is None:
            return None
        wp = _points(self.route.waypoints, 3)
        if len(wp) < 2:
            return None
        cw = self._centroids(wp)
        c = self._centroids(self.object[None])
        d, _ = geometry.point_segment_distance(c, cw[:-1], cw[1:])
        return round(float(d.min()), 5)

    def _centroids(self, poses: np.ndarray) -> np.ndarray:
        """The object's centroid (world) at each of the poses (N, 3) of its frame."""
        c = geometry.centroid(self.poly)
        return np.array([geometry.transform(c[None], q)[0] for q in poses]).reshape(-1, 2)


def describe(ev: Event, phase: str) -> str:
    """One log line for a plan event."""
    match ev:
        case PhaseEvent():
            return f"phase: {phase}"
        case CaptureEvent(robots=robots):
            return (
                f"capture planned: {len(robots)} robots {robots}, form closure "
                f"{ev.form_closure}, objective {ev.objective}"
            )
        case ArrestEvent():
            return f"object arrested (arrival spread {ev.arrival_spread_s} s)"
        case RouteEvent():
            return f"route planned: {ev.length_m} m, {len(ev.subgoals)} subgoals"
        case RearrangeEvent():
            return f"re-arranging for pushing: moving {ev.moving}"
        case TransportEvent(plan=plan):
            acts = plan.get("first_actions", [])
            return f"local plan ({plan.get('strategy')}, {plan.get('status')}): {acts}"
        case FailureEvent():
            return f"FAILED: {ev.reason}: {ev.detail}"
    brief = json.dumps(ev.to_dict(), separators=(",", ":"), default=str)
    return f"{ev.kind}: {brief[:300]}"


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return None
    return float(v)


def _is_point(p: Any) -> bool:
    return (
        isinstance(p, list | tuple) and len(p) >= 2 and all(_number(v) is not None for v in p[:2])
    )


def _points(rows: Any, width: int) -> np.ndarray:
    """Rows of numbers as an (N, width) array, skipping malformed rows."""
    good = [
        [float(v) for v in r[:width]]
        for r in rows or []
        if isinstance(r, list | tuple)
        and len(r) >= width
        and all(_number(v) is not None for v in r[:width])
    ]
    return np.asarray(good, dtype=float).reshape(-1, width)


def _inward_normal(poly: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The inward unit normal of the polygon edge nearest to ``p`` (object frame)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    d, _ = geometry.point_segment_distance(p[None], a, b)
    return -geometry.outward_normals(poly)[int(np.argmin(d[0]))]


def _transport_ids(tr: TransportEvent, capture: CaptureEvent | None) -> list[str]:
    """The robot ids of a transport plan's rows (its ``robots``, else the capture's robots)."""
    ids = tr.robots or (capture.robots if capture is not None else [])
    return [str(i) for i in ids]


def _list(value: Any) -> list:
    """A plan's list field as a list (anything else, missing or malformed: empty)."""
    return value if isinstance(value, list) else []
