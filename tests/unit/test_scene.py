"""The Foxglove scene builder: every message it makes follows the published Foxglove JSON
Schemas; frames follow the run's clock at ``log.scene_hz``; robots are coloured by role and
phase; the plan (capture points, route, pushers and their forces) and the log lines appear."""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from controller import geometry, wire
from controller.events import CaptureEvent, RearrangeEvent, RouteEvent, TransportEvent
from controller.io.recorder import read_log
from controller.scene import primitives as P
from controller.scene.builder import (
    ACTION_COLORS,
    GREY,
    LOST,
    PHASE_COLORS,
    SCENE_TOPICS,
    SceneBuilder,
)
from tests.support.config import make_config
from tests.support.foxglove import errors

GOLDEN = Path(__file__).resolve().parents[1] / "replay" / "data" / "capture.mcap"
EPOCH = 946_684_800.0


def payload(msg: wire.Message) -> dict:
    return json.loads(wire.encode(msg))


class Stream:
    """A hand-made run: ticks of robot states, object state and truth, plan events."""

    def __init__(self, cfg, rate_hz: float = 10.0) -> None:
        self.cfg = cfg
        self.b = SceneBuilder(cfg, time_offset=EPOCH, rate_hz=rate_hz)
        self.out: list = []
        self.k = lambda topic, **p: wire.key(topic, cfg.fleet.name, **p)

    def feed(self, key: str, msg: wire.Message) -> None:
        self.out += self.b.ingest(key, payload(msg))

    def tick(self, t: float, poses: dict[str, tuple], obj=(2.0, 3.0, 0.0), stale=()) -> None:
        self.feed(self.k("truth_object"), wire.PoseMeasurement(t=t, x=obj[0], y=obj[1], theta=0))
        for rid in poses:
            self.feed(self.k("robot_cmd", id=rid), wire.Twist2D(t=t, vx=0.1))
        for rid, (x, y, th) in poses.items():
            st = wire.RobotState(t=t, id=rid, x=x, y=y, theta=th, vx=0.1, stale=rid in stale)
            self.feed(self.k("robot_state", id=rid), st)
        self.feed(self.k("object_state"), wire.ObjectState(t=t, x=obj[0], y=obj[1], theta=obj[2]))

    def event(self, t: float, kind: str, phase: str, data: dict) -> None:
        ev = wire.PlanEvent(t=t, kind=kind, phase=phase, data=data)
        self.feed(self.k("plan", what=kind), ev)

    def done(self) -> list:
        self.out += self.b.flush()
        return self.out


def ring(cfg, t: float = 0.0) -> dict[str, tuple]:
    return {r.id: (r.start[0] + 0.1 * t, r.start[1], r.start[2]) for r in cfg.robots}


TRANSPORT_PLAN = {
    "strategy": "sa",
    "status": "ok",
    "interval": 0.5,
    "robots": ["r1", "r2", "r3"],
    "first_actions": ["push", "follow", "relocate"],
    "velocities": [[0.1, 0.0], [0.1, 0.0], [0.0, 0.2]],
    "contact_points": [[0.0, 0.2], [0.5, 0.0], None],
    "object_poses": [[2.0, 3.0, 0.0], [2.05, 3.0, 0.0], [2.1, 3.0, 0.01]],
    "forces": [[3.5, 0.0, 0.0], [2.0, 0.0, 0.0]],
    "lp_status": ["ok", "ok"],
    "energy": {"total": 1.0},
}


def transport_event(t: float) -> dict:
    """A ``plan/transport`` payload as the push stage writes it, around ``TRANSPORT_PLAN``."""
    plan = {k: v for k, v in TRANSPORT_PLAN.items() if k != "robots"}
    robots = TRANSPORT_PLAN["robots"]
    ev = TransportEvent(t=t, robots=robots, plan=plan, relocating={}, plan_age_s=0.0)
    return ev.to_dict()


@pytest.fixture
def job():
    """Capture, route, re-arrangement and transport events over 3 s of 20 Hz ticks."""
    cfg = make_config(transport=True)  # with its goal
    s = Stream(cfg)
    capture = CaptureEvent(
        points=[[0, 0.2], [1, 0.2]], normals=[[-1, 0], [1, 0]], robots=["r1", "r2"],
        objective=1.0, form_closure=True, robots_needed=2, hold_capacity=1.0, reinforced=0,
        pinned=False, wall_contacts=0, unavailable=[],
    )  # fmt: skip
    s.event(0.05, "capture", "approach", capture.to_dict())
    for k in range(1, 61):
        t = 0.05 * k
        if k == 20:
            s.event(t, "phase", "hold", {"phase": "hold", "t": t})
        if k == 30:
            route = RouteEvent(
                t=t,
                waypoints=[[2, 3, 0], [5, 3, 0], [9.5, 9.5, 0]],
                subgoals=[[5, 3, 0], [9.5, 9.5, 0]],
                length_m=11.0,
                cost_s=12.0,
                replans=0,
            )
            s.event(t, "route", "route", route.to_dict())
        if k == 35:
            rearrange = RearrangeEvent(
                t=t, direction=[1.0, 0.0], pushers=1, basis="eq5", eq5_value=1.0,
                moving=["r1"], contacts={"r1": [0.0, 0.3]},
            )  # fmt: skip
            s.event(t, "rearrange", "rearrange", rearrange.to_dict())
        if k == 40:
            s.event(t, "transport", "transport", transport_event(t))
        s.tick(t, ring(cfg, t), obj=(2.0 + 0.01 * k, 3.0, 0.0))
    s.event(3.0, "failure", "failed", {"reason": "stalled", "t": 3.0, "detail": "no progress"})
    return cfg, s.done()


def test_every_message_follows_the_published_foxglove_schemas(job):
    _, out = job
    assert {m.topic for m in out} == set(SCENE_TOPICS)
    for m in out:
        assert m.schema == SCENE_TOPICS[m.topic]
        assert not errors(m.schema, m.data), (m.topic, errors(m.schema, m.data)[:3])
        json.loads(m.payload())  # plain JSON, no NaN


def test_every_message_of_a_recorded_run_follows_the_schemas():
    """The builder over the bus messages of a real run (the golden capture log)."""
    from controller.replay.log import load_run

    cfg = load_run(GOLDEN).config
    b = SceneBuilder(cfg, time_offset=EPOCH)
    out = []
    for rec in read_log(GOLDEN):
        if not rec.topic.startswith("/"):
            out += b.ingest(rec.topic, rec.decoded())
    out += b.flush()
    bad = [(m.topic, e) for m in out for e in errors(m.schema, m.data)]
    assert not bad, bad[:3]
    counts = Counter(m.topic for m in out)
    assert counts["/tf"] > 100 and counts["/scene/robots"] > 0 and counts["/log"] >= 5
    robots = {e["id"] for m in out if m.topic == "/scene/robots" for e in m.data["entities"]}
    assert robots == {f"robot/{r}" for r in cfg.robot_ids}


def test_the_strict_check_catches_a_misspelt_field():
    ent = P.entity("x", 1.0, "world")
    assert not errors("foxglove.SceneUpdate", P.scene_update([ent]))
    ent["frame"] = ent.pop("frame_id")
    assert errors("foxglove.SceneUpdate", P.scene_update([ent]))


def test_frames_follow_the_run_clock_at_scene_hz(job):
    _, out = job
    tf = [m for m in out if m.topic == "/tf"]
    # 3 s of 20 Hz ticks at 10 Hz: a frame every other tick, plus the last one
    assert 29 <= len(tf) <= 32
    dt = np.diff([m.t for m in tf])
    assert np.all(dt[:-1] >= 0.1 - 1e-9)  # the last one: the flush at the end of the run
    # stamps are the run's clock on the sim epoch
    st = tf[0].data["transforms"][0]["timestamp"]
    assert st["sec"] + st["nsec"] / 1e9 == pytest.approx(EPOCH + tf[0].t, abs=1e-6)


def test_the_world_and_every_entity_are_sent_again_now_and_then(job):
    _, out = job
    world = [m.t for m in out if m.topic == "/scene/world"]
    assert len(world) >= 2 and np.all(np.diff(world) <= 2.0 + 0.1)
    ids = {e["id"] for m in out if m.topic == "/scene/world" for e in m.data["entities"]}
    assert {"room", "obstacle/0", "obstacle/1", "obstacle/2", "goal"} <= ids


def last_entity(out, topic: str, eid: str) -> dict:
    return [e for m in out if m.topic == topic for e in m.data["entities"] if e["id"] == eid][-1]


def entity_before(out, topic: str, eid: str, t: float) -> dict:
    return [
        e for m in out if m.topic == topic and m.t < t for e in m.data["entities"] if e["id"] == eid
    ][-1]


def rgba(c: dict) -> tuple:
    return (c["r"], c["g"], c["b"], c["a"])


def test_robots_are_coloured_by_role_and_phase(job):
    cfg, out = job
    # approach: the capture robots r1, r2 in the phase's colour, a spare grey
    r1 = entity_before(out, "/scene/robots", "robot/r1", 1.0)
    r5 = entity_before(out, "/scene/robots", "robot/r5", 1.0)
    assert rgba(r1["cylinders"][0]["color"]) == pytest.approx(PHASE_COLORS["approach"])
    assert rgba(r5["cylinders"][0]["color"]) == pytest.approx(GREY)
    assert r1["frame_id"] == "robot/r1" and r1["frame_locked"]
    assert r1["cylinders"][0]["size"]["x"] == pytest.approx(2 * cfg.robot("r1").radius)
    # transport: each robot of the plan in its action's colour, labelled with it
    r1 = entity_before(out, "/scene/robots", "robot/r1", 3.0)
    r3 = entity_before(out, "/scene/robots", "robot/r3", 3.0)
    assert rgba(r1["cylinders"][0]["color"]) == pytest.approx(ACTION_COLORS["push"])
    assert rgba(r3["cylinders"][0]["color"]) == pytest.approx(ACTION_COLORS["relocate"])
    assert r1["texts"][0]["text"] == "r1 push"


def test_stale_and_lost_robots_are_shown(job):
    cfg = make_config()
    s = Stream(cfg)
    s.tick(0.05, ring(cfg), stale=("r2",))
    s.feed(
        s.k("robot_event", id="r3"),
        wire.PlanEvent(t=0.06, kind="link_lost", data={"detail": "no heartbeat"}),
    )
    s.tick(0.10, ring(cfg), stale=("r2",))
    out = s.done()
    r2 = last_entity(out, "/scene/robots", "robot/r2")
    r3 = last_entity(out, "/scene/robots", "robot/r3")
    assert r2["cylinders"][0]["color"]["a"] < 0.5 and "stale" in r2["texts"][0]["text"]
    assert rgba(r3["cylinders"][0]["color"]) == LOST
    logs = [m.data for m in out if m.topic == "/log"]
    assert any(d["level"] == P.LOG_ERROR and "link_lost" in d["message"] for d in logs)


def test_the_plan_is_drawn(job):
    cfg, out = job
    cap = entity_before(out, "/scene/plan", "capture", 1.0)
    assert cap["frame_id"] == "object" and len(cap["spheres"]) == 2 and len(cap["arrows"]) == 2
    assert [s["pose"]["position"]["x"] for s in cap["spheres"]] == [0, 1]
    # the push normal points into the object: from (0, 0.2) + 0.3 (-1, 0), heading +x
    a = cap["arrows"][0]
    assert a["pose"]["position"]["x"] == pytest.approx(-0.3) and a["pose"]["orientation"][
        "w"
    ] == pytest.approx(1.0)
    route = last_entity(out, "/scene/plan", "route")
    assert len(route["lines"][0]["points"]) == 3 and len(route["lines"]) == 1 + 2  # + subgoals
    poses = [m for m in out if m.topic == "/scene/route"][-1].data
    assert len(poses["poses"]) == 3 and poses["frame_id"] == "world"
    forces = entity_before(out, "/scene/plan", "transport/forces", 3.0)
    assert len(forces["arrows"]) == 1  # the one robot pushing in the first interval
    f = forces["arrows"][0]
    assert f["shaft_length"] + f["head_length"] == pytest.approx(
        3.5 * 0.01 if 3.5 * 0.01 > 0.05 else 0.05
    )
    # the pusher's arrow ends at its contact point (0, 0.2) on the edge x = 0, pushing +x
    assert f["pose"]["position"]["x"] + f["shaft_length"] + f["head_length"] == pytest.approx(-0.02)
    # after the failure the transport's arrows are gone
    assert last_entity(out, "/scene/plan", "transport/forces")["arrows"] == []


def test_log_lines_and_stats(job):
    cfg, out = job
    logs = [m.data for m in out if m.topic == "/log"]
    words = [d["message"] for d in logs]
    assert any(w.startswith("capture planned: 2 robots") for w in words)
    assert "phase: hold" in words and any(w.startswith("route planned") for w in words)
    fail = [d for d in logs if d["message"].startswith("FAILED")]
    assert fail and fail[0]["level"] == P.LOG_ERROR
    stats = [m.data for m in out if m.topic == "/scene/stats"]
    assert stats[-1]["phase"] == "failed" and stats[-1]["estop"] is False
    during = [s for s in stats if s["phase"] == "transport"]
    assert during and during[0]["pushers"] == 1 and during[0]["push_force_n"] == pytest.approx(3.5)
    assert during[0]["lateral_deviation_m"] is not None
    # the smallest robot gap is that of the robots' discs at their poses
    xy = np.array([p[:2] for p in ring(cfg, stats[-1]["t"]).values()])
    radii = [r.radius for r in cfg.robots]
    assert stats[-1]["min_clearance_m"] == pytest.approx(
        float(geometry.min_disc_gap(xy, radii)), abs=1e-4
    )


def test_an_estop_goes_to_the_log_and_the_stats():
    cfg = make_config()
    s = Stream(cfg)
    s.tick(0.05, ring(cfg))
    # stamped with an operator's wall clock in a dry run: taken at the run's time
    s.feed(s.k("estop"), wire.EStop(t=1.7e9, engaged=True, source="op@lab", reason="test"))
    s.tick(0.10, ring(cfg))
    out = s.done()
    log = [m for m in out if m.topic == "/log"][-1]
    assert log.data["level"] == P.LOG_ERROR and "E-STOP engaged by op@lab" in log.data["message"]
    assert log.t == pytest.approx(0.05)
    assert [m.data for m in out if m.topic == "/scene/stats"][-1]["estop"] is True


def test_prism_top_covers_a_concave_polygon():
    ell = np.array([[0, 0], [1, 0], [1, 0.4], [0.4, 0.4], [0.4, 1], [0, 1]], float)
    tris = P.triangulate(ell)
    area = sum(abs(geometry.signed_area(ell[list(t)])) for t in tris)
    assert len(tris) == len(ell) - 2 and area == pytest.approx(geometry.signed_area(ell))
    # every triangle lies inside the polygon (its centroid does)
    cents = np.array([ell[list(t)].mean(axis=0) for t in tris])
    assert geometry.points_in_polygon(cents, ell).all()
    prism = P.prism(ell, 0.25, (1, 0, 0, 1))
    assert len(prism["points"]) == 3 * (len(tris) + 2 * len(ell))


def test_scene_hz_zero_makes_no_scene():
    cfg = make_config({"log": {"scene_hz": 0.0}})
    b = SceneBuilder(cfg)
    msg = wire.RobotState(t=0.1, id="r1", x=1, y=1, theta=0)
    assert b.ingest(wire.key("robot_state", cfg.fleet.name, id="r1"), payload(msg)) == []
    assert math.isinf(b.period)
