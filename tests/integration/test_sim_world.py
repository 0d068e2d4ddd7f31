"""The stand-in worlds: physics behaviour of the pybullet world, the shared interface of both
backends, the convex decomposition, and the pose sensors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from controller import geometry
from controller.config import FleetConfig, parse_config
from sim_backend.factory import make_world
from sim_backend.ideal import IdealWorld
from sim_backend.motion import ObjectScript
from sim_backend.pybullet_world import PybulletWorld, convex_pieces
from sim_backend.sensors import PoseSensor, make_sensors

G = 9.81
L_SHAPE = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]]
BOX = [[0.0, 0.0], [0.9, 0.0], [0.9, 0.4], [0.0, 0.4]]
INERT = {"kind": "inert"}  # no drive: limp from the start (a plain crate)
BACKENDS = ["ideal", "pybullet"]


def config(
    robots: list[dict] | None = None,
    polygon: list[list[float]] = L_SHAPE,
    start: tuple[float, float, float] = (5.0, 5.0, 0.0),
    motion: dict | None = None,
    mass: float = 4.0,
    mu: float = 0.2,
    contact_friction: float = 0.0,
    backend: str = "pybullet",
    sim: dict | None = None,
    obstacles: list[list[list[float]]] = (),
) -> FleetConfig:
    robots = robots or [{"id": "r0", "kind": "omni", "start": [0.5, 0.5, 0.0]}]
    return parse_config(
        {
            "fleet": {"name": "test"},
            "object": {
                "polygon": polygon,
                "mass": mass,
                "floor_friction": mu,
                "contact_friction": contact_friction,
                "start": list(start),
                "goal": [8.0, 8.0, 0.0],
                "motion": motion or {"kind": "static"},
            },
            "robots": robots,
            "sim": {"backend": backend, **(sim or {})},
            "obstacles": [{"polygon": o} for o in obstacles],
        }
    )


def robot(rid: str, kind: str, x: float, y: float, th: float = 0.0, **kw) -> dict:
    return {"id": rid, "kind": kind, "start": [x, y, th], **kw}


@pytest.fixture
def worlds():
    made = []

    def build(cfg: FleetConfig):
        w = make_world(cfg)
        made.append(w)
        return w

    yield build
    for w in made:
        w.close()


# --------------------------------------------------------------------------- decomposition


@pytest.mark.parametrize(
    "poly",
    [
        L_SHAPE,
        [[0, 0], [1, 0], [1, 1], [0.8, 1], [0.8, 0.2], [0.2, 0.2], [0.2, 1], [0, 1]],  # U
        [[0, 0], [2, 0], [2, 2], [1, 0.5], [0, 2]],  # arrow head
        BOX,
    ],
)
def test_convex_pieces_tile_the_polygon(poly):
    pieces = convex_pieces(np.array(poly, dtype=float))
    target = shapely.Polygon(poly)
    union = shapely.union_all([shapely.Polygon(p) for p in pieces])
    assert union.symmetric_difference(target).area < 1e-9
    assert sum(shapely.Polygon(p).area for p in pieces) == pytest.approx(target.area)
    for p in pieces:
        assert geometry.signed_area(p) > 0
        hull = geometry.convex_hull(p)
        assert abs(geometry.signed_area(hull) - geometry.signed_area(p)) < 1e-12


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.3, 1.0), min_size=4, max_size=12), st.floats(0.0, 1.0))
def test_convex_pieces_tile_star_polygons(radii, jitter):
    """Property: star-shaped polygons (simple, often concave) are tiled by convex pieces."""
    n = len(radii)
    ang = (np.arange(n) + 0.4 * jitter) * 2 * np.pi / n
    poly = np.stack([np.cos(ang), np.sin(ang)], axis=1) * np.array(radii)[:, None]
    pieces = convex_pieces(poly)
    union = shapely.union_all([shapely.Polygon(p) for p in pieces])
    assert union.symmetric_difference(shapely.Polygon(poly)).area < 1e-9
    for p in pieces:
        hull = geometry.convex_hull(p)
        assert abs(geometry.signed_area(hull) - geometry.signed_area(p)) < 1e-9
    assert len(pieces) <= n - 2


def test_robot_sits_in_the_notch_of_an_l(worlds):
    """The compound covers the L but not its notch: a robot reaches the inner corner."""
    cfg = config([robot("r0", "omni", 6.3, 6.3, max_force=2.0)], polygon=L_SHAPE, motion=INERT)
    w = worlds(cfg)
    w.set_command("r0", -0.15, -0.15, 0.0)
    w.step(6.0)
    xy = w.robot_pose("r0")[:2]
    # Inner corner of the notch at (5.4, 5.4); a disc of radius 0.1 touches both inner faces.
    assert np.linalg.norm(xy - [5.5, 5.5]) < 0.01
    # A convex hull would have stopped it outside the notch.
    assert geometry.points_in_polygon([xy], geometry.convex_hull(np.array(L_SHAPE) + 5.0))[0]
    assert w.check().object_penetration < 0.003
    assert np.allclose(w.object_pose(), [5.0, 5.0, 0.0], atol=5e-3)  # a 2 N robot bumped it


# --------------------------------------------------------------------------- the interface, both


@pytest.mark.parametrize("backend", BACKENDS)
def test_start_poses_as_written(worlds, backend):
    cfg = config(
        [robot("a", "omni", 1.0, 2.0, 0.5), robot("b", "diff", 3.0, 1.0, -2.0)],
        start=(4.0, 3.0, 0.7),
        backend=backend,
    )
    w = worlds(cfg)
    assert w.robot_ids == ("a", "b")
    assert np.allclose(w.object_pose(), [4.0, 3.0, 0.7], atol=1e-9)
    assert np.allclose(w.robot_pose("a"), [1.0, 2.0, 0.5], atol=1e-9)
    assert np.allclose(w.robot_pose("b"), [3.0, 1.0, -2.0], atol=1e-9)
    assert w.t == 0.0 and w.object_alive and w.object_gave_up_at is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_omni_follows_body_frame_command(worlds, backend):
    th = math.pi / 2
    w = worlds(config([robot("r", "omni", 2.0, 2.0, th)], backend=backend))
    w.set_command("r", 0.2, 0.1, 0.0)
    w.step(1.0)
    expect = np.array([2.0, 2.0]) + geometry.rot(th) @ [0.2, 0.1]
    assert np.linalg.norm(w.robot_pose("r")[:2] - expect) < 0.005
    assert np.allclose(w.robot_velocity("r")[:2], geometry.rot(th) @ [0.2, 0.1], atol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_omni_turns_while_translating(worlds, backend):
    """Body-frame velocity is re-aimed as the robot turns: a forward command with yaw traces a
    circle of radius v / wz."""
    w = worlds(config([robot("r", "omni", 4.0, 4.0, 0.0)], backend=backend))
    w.set_command("r", 0.2, 0.0, 0.5)
    w.step(math.pi / 0.5)  # half a turn
    x, y, th = w.robot_pose("r")
    assert abs(abs(th) - math.pi) < 0.02
    assert np.linalg.norm([x - 4.0, y - 4.8]) < 0.02  # diameter 2 v / wz = 0.8 m


@pytest.mark.parametrize("backend", BACKENDS)
def test_diff_ignores_vy(worlds, backend):
    th = 0.3
    w = worlds(config([robot("r", "diff", 2.0, 2.0, th)], backend=backend))
    w.set_command("r", 0.2, 0.3, 0.0)
    w.step(1.0)
    d = geometry.rot(th).T @ (w.robot_pose("r")[:2] - [2.0, 2.0])
    assert d[0] == pytest.approx(0.2, abs=0.005)
    assert abs(d[1]) < 1e-3


@pytest.mark.parametrize("backend", BACKENDS)
def test_diff_arc_has_no_sideways_velocity(worlds, backend):
    w = worlds(config([robot("r", "diff", 3.0, 3.0, 0.0, max_yaw_rate=2.0)], backend=backend))
    w.set_command("r", 0.3, 0.0, 1.0)
    worst = 0.0
    for _ in range(40):
        w.step(0.05)
        _, _, th = w.robot_pose("r")
        v_body = geometry.rot(th).T @ w.robot_velocity("r")[:2]
        worst = max(worst, abs(v_body[1]))
    assert worst < 0.01  # m/s; the forward speed is 0.3


@pytest.mark.parametrize("backend", BACKENDS)
def test_live_object_follows_its_sine_script(worlds, backend):
    motion = {"kind": "sine", "speed": 0.1, "amplitude": 0.4, "wavelength": 2.0, "max_force": 4.0}
    cfg = config(start=(2.0, 5.0, 0.0), motion=motion, backend=backend)
    w = worlds(cfg)
    script = ObjectScript(cfg.object.motion, cfg.object.start)
    worst = 0.0
    for _ in range(20):
        w.step(0.5)
        ref, _ = script.reference(w.t)
        worst = max(worst, float(np.linalg.norm(w.object_pose()[:2] - ref[:2])))
        assert abs(geometry.wrap_angle(w.object_pose()[2])) < 0.02
    assert worst < 0.03
    assert w.object_pose()[0] > 2.9  # it travelled about a metre


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_held_script_waits_at_its_start_then_runs_its_path_from_the_start(worlds, backend):
    """``fleet world`` with ``sim.object_start = "resume"``: however long the bring-up takes,
    the object stays at its start; its path then begins where a fresh one would."""
    motion = {"kind": "sine", "speed": 0.1, "amplitude": 0.4, "wavelength": 2.0, "max_force": 4.0}
    cfg = config(start=(2.0, 5.0, 0.0), motion=motion, backend=backend)
    w = worlds(cfg)
    w.hold_object()
    assert w.object_waiting
    w.step(60.0)  # a minute of bring-up
    assert np.allclose(w.object_pose(), [2.0, 5.0, 0.0], atol=2e-3)
    assert w.object_alive  # holding its start is not being thwarted
    w.start_object()
    t0 = w.t
    assert not w.object_waiting
    script = ObjectScript(cfg.object.motion, cfg.object.start)
    for _ in range(10):
        w.step(0.5)
        ref, _ = script.reference(w.t - t0)  # the fresh path, shifted to the resume
        assert np.linalg.norm(w.object_pose()[:2] - ref[:2]) < 0.03
    assert w.object_pose()[0] > 2.4
    w.start_object()  # a second resume changes nothing
    ref, _ = script.reference(w.t - t0)
    assert np.linalg.norm(w.object_pose()[:2] - ref[:2]) < 0.03


@pytest.mark.parametrize("backend", BACKENDS)
def test_held_object_gives_up_by_its_own_physics_then_stays_put(worlds, backend):
    """A driven object that cannot follow its script (a 20 N robot in its way) goes limp after
    ``give_up_after`` s of being thwarted: the world decides, nobody tells it. Limp, it stays
    where it is. The same object running free keeps its drive."""
    motion = {"kind": "line", "speed": 0.1, "max_force": 4.0, "give_up_after": 1.0}
    blocker = [robot("r", "omni", 6.12, 5.2, 0.0, max_force=20.0)]  # 0.12 m ahead of it
    w = worlds(config(blocker, polygon=BOX, start=(5.0, 5.0, 0.0), motion=motion, backend=backend))
    w.step(1.0)
    assert w.object_alive  # still running toward the robot
    w.step(2.5)  # in contact from about 1.2 s, thwarted for a second after that
    assert not w.object_alive
    assert 1.8 < w.object_gave_up_at < 3.0
    here = w.object_pose()
    w.step(2.0)
    assert np.allclose(w.object_pose(), here, atol=1e-3)
    assert np.allclose(w.object_velocity(), 0.0, atol=1e-3)
    free = worlds(config(polygon=BOX, start=(5.0, 5.0, 0.0), motion=motion, backend=backend))
    free.step(4.0)
    assert free.object_alive and free.object_pose()[0] > 5.35


@pytest.mark.parametrize("backend", BACKENDS)
def test_inert_object_is_limp_from_the_start(worlds, backend):
    w = worlds(config(start=(3.0, 3.0, 0.0), motion=INERT, backend=backend))
    assert not w.object_alive and w.object_gave_up_at == 0.0
    w.step(1.0)
    assert np.allclose(w.object_pose(), [3.0, 3.0, 0.0], atol=1e-4)


@pytest.mark.parametrize("backend", BACKENDS)
def test_evading_object_flees_the_nearest_robot(worlds, backend):
    motion = {"kind": "evade", "speed": 0.0, "max_speed": 0.2, "flee_radius": 1.5}
    cfg = config(
        [robot("r", "omni", 4.6, 5.0, 0.0)], start=(5.0, 5.0, 0.0), motion=motion, backend=backend
    )
    w = worlds(cfg)
    c0 = geometry.centroid(L_SHAPE)

    def gap() -> float:
        c = geometry.transform([c0], w.object_pose())[0]
        return float(np.linalg.norm(c - w.robot_pose("r")[:2]))

    start_gap = gap()
    w.step(2.0)
    assert gap() > start_gap + 0.1


@pytest.mark.parametrize("backend", BACKENDS)
def test_check_reports_clearance(worlds, backend):
    cfg = config([robot("a", "omni", 1.0, 1.0), robot("b", "omni", 1.25, 1.0)], backend=backend)
    chk = worlds(cfg).check()
    assert chk.min_clearance == pytest.approx(0.05, abs=1e-9)
    assert chk.object_penetration == 0.0
    assert chk.obstacle_contacts == ()


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_same_truth(backend):
    motion = {"kind": "evade", "speed": 0.05, "max_speed": 0.2}
    robots = [robot("a", "omni", 3.0, 5.2, 0.0), robot("b", "diff", 6.5, 5.5, 3.0)]
    runs = []
    for _ in range(2):
        w = make_world(config(robots, start=(5.0, 5.0, 0.0), motion=motion, backend=backend))
        trace = []
        for k in range(30):
            w.set_command("a", 0.3, 0.05 * math.sin(k), 0.2)
            w.set_command("b", 0.2, 0.0, -0.3)
            w.step(0.05)
            trace.append(np.concatenate([w.object_pose(), w.robot_pose("a"), w.robot_pose("b")]))
        w.close()
        runs.append(np.array(trace))
    assert np.array_equal(runs[0], runs[1])


def test_factory_chooses_backend():
    w = make_world(config(backend="ideal"))
    assert isinstance(w, IdealWorld)
    w.close()
    w = make_world(config(backend="pybullet"))
    assert isinstance(w, PybulletWorld)
    w.close()


# --------------------------------------------------------------------------- pybullet physics


@pytest.mark.parametrize(
    ("mu", "mass", "direction"), [(0.2, 4.0, 0.0), (0.2, 4.0, 0.8), (0.5, 1.5, 2.0)]
)
def test_floor_friction_calibrated(worlds, mu, mass, direction):
    """The force to slide the limp object is mu * m * g within 10 %."""
    w = worlds(config(polygon=L_SHAPE, mass=mass, mu=mu, motion=INERT))
    w.step(0.2)
    u = np.array([math.cos(direction), math.sin(direction)])
    limit = mu * mass * G
    # 0.9 of the limit: it holds.
    start = w.object_pose()
    for _ in range(240):
        w.apply_object_force(tuple(0.9 * limit * u))
        w.step(w.dt)
    assert np.linalg.norm(w.object_pose()[:2] - start[:2]) < 1e-3
    # 1.5 of the limit: it slides, and the friction force is read off the acceleration.
    push = 1.5 * limit
    speeds = []
    for _ in range(240):
        w.apply_object_force(tuple(push * u))
        w.step(w.dt)
        speeds.append(float(u @ w.object_velocity()[:2]))
    accel = (speeds[-1] - speeds[119]) / (120 * w.dt)
    friction = push - mass * accel
    assert friction == pytest.approx(limit, rel=0.10)


def test_one_weak_robot_stalls_four_push(worlds):
    """Yamashita's 2 N robots against a 4 kg box at mu 0.2 (needs 7.85 N)."""
    tall_box = [[0.0, 0.0], [0.4, 0.0], [0.4, 0.9], [0.0, 0.9]]  # face x = 5 spans y 4.8 .. 5.7

    def run(n: int) -> float:
        ys = [5.25] if n == 1 else [4.89, 5.1, 5.31, 5.52]
        robots = [robot(f"r{k}", "omni", 4.89, y, 0.0, max_force=2.0) for k, y in enumerate(ys)]
        w = worlds(config(robots, polygon=tall_box, start=(5.0, 4.8, 0.0), motion=INERT))
        for rid in w.robot_ids:
            w.set_command(rid, 0.1, 0.0, 0.0)
        x0 = w.object_pose()[0]
        w.step(3.0)
        return w.object_pose()[0] - x0

    assert run(1) < 0.005
    assert run(4) > 0.05


def test_live_object_escapes_a_weak_robot_and_is_held_by_a_strong_one(worlds):
    motion = {"kind": "line", "speed": 0.1, "max_force": 4.0}

    def run(force: float) -> float:
        cfg = config(
            [robot("r", "omni", 6.12, 5.2, 0.0, max_force=force)],
            polygon=BOX,
            start=(5.0, 5.0, 0.0),
            motion=motion,
        )
        w = worlds(cfg)
        w.step(4.0)
        return w.object_pose()[0] - 5.0

    assert run(2.0) > 0.25  # its 4 N drive beats a 2 N robot
    assert 0.10 < run(20.0) < 0.13  # a 20 N one stops it on contact (0.12 m away)


def test_diff_robot_resists_sideways_pushes_like_tyres(worlds):
    w = worlds(config([robot("r", "diff", 3.0, 3.0, 0.0, max_force=2.0, mass=2.0)], polygon=BOX))
    grip = 1.0 * 2.0 * G  # tyre_grip * m * g
    for _ in range(240):  # 10 N sideways, held
        w.apply_robot_force("r", (0.0, 10.0))
        w.step(w.dt)
    assert abs(w.robot_pose("r")[1] - 3.0) < 2e-3
    for _ in range(240):  # 10 N forward: its 2 N drive gives way, as a motor would
        w.apply_robot_force("r", (10.0, 0.0))
        w.step(w.dt)
    assert w.robot_pose("r")[0] - 3.0 > 0.5
    y0 = w.robot_pose("r")[1]
    for _ in range(240):  # beyond the tyres' grip it skids
        w.apply_robot_force("r", (0.0, 2.0 * grip))
        w.step(w.dt)
    assert w.robot_pose("r")[1] - y0 > 0.5


def test_robot_push_force_is_bounded(worlds):
    """A 6 N robot drives into a wall: it stalls, and a 6 N external pull back undoes it."""
    w = worlds(config([robot("r", "omni", 12.2, 6.0, 0.0, max_force=6.0)]))
    w.set_command("r", 0.2, 0.0, 0.0)
    w.step(3.0)
    assert w.robot_pose("r")[0] == pytest.approx(12.7, abs=0.003)  # touching the east wall
    assert w.check().obstacle_contacts == ()
    for _ in range(240):
        w.apply_robot_force("r", (-8.0, 0.0))
        w.step(w.dt)
    assert w.robot_pose("r")[0] < 12.6


@pytest.mark.parametrize(("contact_friction", "drags"), [(0.0, False), (1.0, True)])
def test_contact_friction_setting(worlds, contact_friction, drags):
    """A robot pressing on the object's face while sliding along it drags the object along only
    when robot-object contacts have friction (0 = Sharma et al.'s frictionless contacts)."""
    tall_box = [[0.0, 0.0], [0.4, 0.0], [0.4, 0.9], [0.0, 0.9]]
    cfg = config(
        [robot("r", "omni", 4.895, 4.9, 0.0, max_force=20.0)],
        polygon=tall_box,
        start=(5.0, 4.8, 0.0),
        contact_friction=contact_friction,
        motion=INERT,
    )
    w = worlds(cfg)
    w.set_command("r", 0.02, 0.2, 0.0)  # press +x into the face, slide +y along it
    w.step(2.0)
    centre = geometry.transform([[0.2, 0.45]], w.object_pose())[0]
    dy = centre[1] - 5.25  # along the face
    # Frictionless, the push stays normal to the face (which turns a little as the box yaws).
    assert (dy > 0.02) if drags else (abs(dy) < 0.005)


def test_concave_obstacle_blocks_with_its_real_shape(worlds):
    """An L-shaped obstacle: a robot drives into its notch and stops at the inner face."""
    obstacle = (np.array(L_SHAPE) * 2.0 + [2.0, 2.0]).tolist()  # notch x, y in 2.8 .. 4
    cfg = config([robot("r", "omni", 3.5, 4.5, 0.0)], obstacles=[obstacle], start=(8.0, 8.0, 0.0))
    w = worlds(cfg)
    w.set_command("r", 0.0, -0.3, 0.0)
    w.step(6.0)
    x, y, _ = w.robot_pose("r")
    assert x == pytest.approx(3.5, abs=1e-3)
    assert y == pytest.approx(2.9, abs=3e-3)  # inner face y = 2.8, radius 0.1


# --------------------------------------------------------------------------- sensors


def _sensor(seed: int, **kw) -> PoseSensor:
    args = dict(
        rate_hz=30.0,
        sigma_xy=0.01,
        sigma_theta=0.02,
        dropout=0.0,
        outlier_rate=0.0,
        outlier_magnitude=0.5,
    )
    args.update(kw)
    return PoseSensor(rng=np.random.default_rng(seed), **args)


def _run(sensor: PoseSensor, seconds: float = 10.0, dt: float = 1 / 240) -> list:
    out = []
    for k in range(int(round(seconds / dt)) + 1):
        out += sensor.sample(k * dt, np.array([1.0, 2.0, 3.1]))
    return out


def test_sensor_rate_noise_and_determinism():
    meas = _run(_sensor(3))
    assert len(meas) == pytest.approx(301, abs=1)
    ts = np.array([m[0] for m in meas])
    assert np.allclose(np.diff(ts), 1 / 30, atol=1 / 240 + 1e-9)
    xy = np.array([m[1:3] for m in meas])
    assert np.std(xy[:, 0] - 1.0) == pytest.approx(0.01, rel=0.2)
    dth = geometry.wrap_angle(np.array([m[3] for m in meas]) - 3.1)
    assert np.std(dth) == pytest.approx(0.02, rel=0.2)
    assert np.all(np.abs(np.array([m[3] for m in meas])) <= math.pi)
    assert meas == _run(_sensor(3))
    assert meas != _run(_sensor(4))


def test_sensor_dropouts_and_outliers():
    s = _sensor(5, dropout=0.2, outlier_rate=0.1, outlier_magnitude=0.5)
    meas = _run(s, seconds=60.0)
    assert s.dropped / (s.dropped + s.emitted) == pytest.approx(0.2, abs=0.04)
    err = np.array([np.hypot(m[1] - 1.0, m[2] - 2.0) for m in meas])
    assert np.mean(err > 0.3) == pytest.approx(0.1, abs=0.03)
    assert s.outliers == int(np.sum(err > 0.3))


def test_sensor_jitter_keeps_rate():
    meas = _run(_sensor(6, jitter=0.3), seconds=20.0)
    assert len(meas) == pytest.approx(601, abs=2)
    gaps = np.diff([m[0] for m in meas])
    assert gaps.min() > 0 and gaps.std() > 1e-3


def test_make_sensors_per_robot_streams_reproducible():
    cfg = config(
        [robot("a", "omni", 1, 1), robot("b", "diff", 2, 2)],
        sim={"seed": 11, "pose_rate_hz": 50.0, "object_pose_rate_hz": 20.0},
    )
    s1, s2 = make_sensors(cfg), make_sensors(cfg)
    assert set(s1.robots) == {"a", "b"}
    assert s1.robots["a"].rate_hz == 50.0 and s1.object.rate_hz == 20.0
    a1, b1, a2 = _run(s1.robots["a"], 1.0), _run(s1.robots["b"], 1.0), _run(s2.robots["a"], 1.0)
    assert a1 == a2
    assert a1 != b1


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "heading, obstacle",
    [
        (0.785, None),  # into the room's north-east corner (default bounds 12.8 m)
        (0.0, [[7.0, 4.0], [7.4, 4.0], [7.4, 7.0], [7.0, 7.0]]),  # into a wall-like obstacle
    ],
)
def test_a_driven_object_stops_at_walls_and_obstacles(worlds, backend, heading, obstacle):
    """The scripted object is solid in both worlds: driven at a wall or an obstacle it stops
    there (it never passes through or leaves the room), and the check says how close it is."""
    motion = {"kind": "line", "speed": 0.4, "heading": heading, "give_up_after": 0.0}
    obstacles = [obstacle] if obstacle else []
    cfg = config(
        polygon=BOX, start=(5.0, 5.0, 0.0), motion=motion, backend=backend, obstacles=obstacles
    )
    w = worlds(cfg)
    w.step(30.0)  # 12 m of script: far beyond the wall
    chk = w.check()
    assert chk.object_clearance > -0.01  # touching at most, never through
    assert chk.object_clearance < 0.05  # it got there and stays pressed against it
    poly = geometry.transform(geometry.ensure_ccw(BOX), w.object_pose())
    assert poly.min() > -0.01 and poly.max() < 12.81  # inside the room
    if obstacle:
        assert poly[:, 0].max() < 7.01
