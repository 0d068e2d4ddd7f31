"""The CBF safety filter: head-on robots keep the margin; obstacles, bounds, stale robots."""

from __future__ import annotations

import numpy as np

from controller.mission.tracking import RobotLimits, track_reversible
from controller.planning.safety import SafetyFilter

BOUNDS = np.array([[0.0, 0.0], [10.0, 10.0]])


def simulate(flt, p, goal_vel, steps=200, dt=0.05, polys=(), stale=None):
    dmin = np.inf
    for _ in range(steps):
        res = flt.filter(p, goal_vel(p), list(polys), stale=stale)
        p = p + dt * res.velocities
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        d[np.eye(len(p), dtype=bool)] = np.inf
        dmin = min(dmin, float(d.min()))
    return p, dmin


def test_head_on_keeps_margin():
    r = np.array([0.1, 0.1])
    flt = SafetyFilter(r, np.array([0.5, 0.5]), BOUNDS, 0, margin=0.05)
    p = np.array([[3.0, 5.0], [7.0, 5.0]])
    _, dmin = simulate(flt, p, lambda p: np.array([[0.5, 0.0], [-0.5, 0.0]]))
    assert dmin >= 0.2 + 0.05 - 1e-3


def test_many_robots_swap_keep_margin():
    n = 12
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    p = 5 + 3 * np.stack([np.cos(ang), np.sin(ang)], 1)
    goal = 5 - 3 * np.stack([np.cos(ang), np.sin(ang)], 1)
    flt = SafetyFilter(np.full(n, 0.1), np.full(n, 0.4), BOUNDS, 0, margin=0.05)

    def vel(p):
        v = goal - p
        s = np.linalg.norm(v, axis=1, keepdims=True)
        return v / np.maximum(s, 1e-9) * np.minimum(s, 0.4)

    _, dmin = simulate(flt, p, vel, steps=300)
    assert dmin >= 0.25 - 2e-3


def test_obstacle_and_bounds():
    box = np.array([[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]])
    flt = SafetyFilter(np.array([0.1]), np.array([0.5]), BOUNDS, 1, margin=0.05)
    p = np.array([[2.0, 5.0]])
    p2, _ = simulate(flt, p, lambda p: np.array([[0.5, 0.0]]), polys=[box])
    assert p2[0, 0] <= 4.0 - 0.1 - 0.05 + 1e-3
    p3, _ = simulate(flt, np.array([[9.0, 9.0]]), lambda p: np.array([[0.5, 0.5]]), polys=[box])
    assert np.all(p3 <= 10.0 - 0.15 + 1e-3)


def test_stale_robot_stays_and_is_avoided():
    r = np.array([0.1, 0.1])
    flt = SafetyFilter(r, np.array([0.5, 0.5]), BOUNDS, 0, margin=0.05)
    stale = np.array([False, True])
    p = np.array([[3.0, 5.0], [5.0, 5.0]])
    p2, dmin = simulate(flt, p, lambda p: np.array([[0.5, 0.0], [0.3, 0.0]]), stale=stale)
    assert np.allclose(p2[1], [5.0, 5.0])
    assert dmin >= 0.25 - 1e-3


def test_warm_equals_cold():
    rng = np.random.default_rng(0)
    n = 8
    p = rng.uniform(1, 9, (n, 2))
    u = rng.uniform(-0.4, 0.4, (n, 2))
    a = SafetyFilter(np.full(n, 0.1), np.full(n, 0.5), BOUNDS, 0)
    b = SafetyFilter(np.full(n, 0.1), np.full(n, 0.5), BOUNDS, 0, warm=False)
    for _ in range(3):
        ra, rb = a.filter(p, u, []), b.filter(p, u, [])
        assert np.allclose(ra.velocities, rb.velocities, atol=2e-3)
        p = p + 0.05 * ra.velocities


def test_robots_inside_each_others_margin_come_no_closer_and_stop_only_without_relaxing():
    # two robots already deep inside each other's margin: no bounded velocity restores it now;
    # relaxed, they may come no closer (and slide on); the third goes on either way
    r = np.full(3, 0.1)
    p = np.array([[5.0, 5.0], [5.05, 5.0], [8.0, 8.0]])
    nom = np.array([[0.3, 0.1], [-0.3, 0.1], [0.2, 0.1]])
    res = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05).filter(p, nom, [])
    assert res.status == "relaxed" and not res.stopped.any()
    closing = res.velocities[0, 0] - res.velocities[1, 0]  # robot 0 is west of robot 1
    assert closing <= 1e-3
    assert np.allclose(res.velocities[:2, 1], 0.1, atol=1e-2)  # the tangent is kept
    assert np.allclose(res.velocities[2], [0.2, 0.1], atol=1e-3)
    # not relaxed (the bare filter's option), both stop and the third goes on
    stop = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05)
    res = stop.filter(p, nom, [], relax=False)
    assert not res.status.startswith("solved")
    assert res.stopped.tolist() == [True, True, False]
    assert np.allclose(res.velocities[:2], 0.0)
    assert np.allclose(res.velocities[2], [0.2, 0.1])


def test_a_robot_the_object_pushes_toward_another_gets_out_of_the_way_with_it():
    # the lab's carry: the crate (moving east at 0.12 m/s) closes on a free robot with another
    # robot just beyond it, both already inside their margins. Recovering them at gamma needs
    # more than max_speed (infeasible); before the relaxation in every phase both stopped and
    # the crate pushed one into the other. Now the first keeps its distance to the crate and
    # the second gives way to the first
    r = np.full(2, 0.1)
    crate = np.array([[3.0, 4.0], [4.0, 4.0], [4.0, 6.0], [3.0, 6.0]])
    p = np.array([[4.12, 5.0], [4.30, 5.0]])
    motion = [(0.12, 0.0, 0.0)]
    flt = SafetyFilter(r, np.full(2, 0.4), BOUNDS, 1, margin=0.05)
    res = flt.filter(p, np.zeros((2, 2)), [crate], motion=motion)
    assert res.status == "relaxed" and not res.stopped.any()
    assert res.velocities[0, 0] >= 0.12 - 2e-3  # no closer to the moving crate
    assert res.velocities[1, 0] >= res.velocities[0, 0] - 2e-3  # nor to each other
    stop = SafetyFilter(r, np.full(2, 0.4), BOUNDS, 1, margin=0.05)
    res = stop.filter(p, np.zeros((2, 2)), [crate], motion=motion, relax=False)
    assert res.stopped.all() and np.allclose(res.velocities, 0.0)


def test_a_robot_squeezed_between_the_object_and_a_wall_slides_out():
    # the object pushes a robot against the west wall: recovering both margins at once is
    # impossible (infeasible before the relaxation); it may not go closer to either, and keeps
    # its motion along the wall
    r = np.full(1, 0.1)
    flt = SafetyFilter(r, np.full(1, 0.4), BOUNDS, 1, margin=0.05)
    wall_gap = BOUNDS[0][0] + 0.12  # inside the wall margin (0.15)
    box = np.array([[wall_gap + 0.12, 4.0], [wall_gap + 1.0, 4.0], [wall_gap + 1.0, 6.0],
                    [wall_gap + 0.12, 6.0]])  # fmt: skip
    p = np.array([[wall_gap, 5.0]])
    res = flt.filter(p, np.array([[0.0, 0.3]]), [box], motion=[(-0.2, 0.0, 0.0)])
    assert res.status == "relaxed" and not res.stopped.any()
    assert res.velocities[0, 1] > 0.2  # it slides along the wall instead of freezing
    assert res.velocities[0, 0] >= -1e-4  # and comes no closer to the wall
    # without the relaxation (the bare filter's option) the same robot stops
    stop = SafetyFilter(r, np.full(1, 0.4), BOUNDS, 1, margin=0.05)
    res = stop.filter(p, np.array([[0.0, 0.3]]), [box], motion=[(-0.2, 0.0, 0.0)], relax=False)
    assert res.stopped.all() and np.allclose(res.velocities, 0.0)


def _encounter(pa, nom_a, nom_b, axis: bool, steps=80, dt=0.05, out=None) -> float:
    """A differential robot (a) and an omni one (b, at the origin) pass each other under the
    guard's pipeline: filter, tracking law, each robot moving the way its wheels let it (the
    differential one only along its axis). The smallest gap between their discs (m)."""
    lim = RobotLimits(np.array([False, True]), np.full(2, 0.4), np.full(2, 2.0), np.full(2, 1.0))
    flt = SafetyFilter(np.full(2, 0.1), np.full(2, 0.4), BOUNDS, 0, margin=0.05,
                       axial=~lim.holonomic)  # fmt: skip
    poses = np.array([[5 + pa[0], 5 + pa[1], pa[2]], [5.0, 5.0, 0.0]])
    gap = np.inf
    for _ in range(steps):
        res = flt.filter(poses[:, :2], np.array([nom_a, nom_b]), [],
                         headings=poses[:, 2] if axis else None)  # fmt: skip
        cmd = track_reversible(poses, res.velocities, lim, aim=res.aim if axis else None)
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        poses[:, 0] += dt * (c * cmd[:, 0] - s * cmd[:, 1])
        poses[:, 1] += dt * (s * cmd[:, 0] + c * cmd[:, 1])
        poses[:, 2] += dt * cmd[:, 2]
        gap = min(gap, float(np.linalg.norm(poses[0, :2] - poses[1, :2]) - 0.2))
    if out is not None:
        out.append(poses.copy())
    return gap


def test_a_differential_robot_keeps_the_margin_it_can_only_keep_along_its_axis():
    """The README lab's collision: r6 (differential) backed along its axis into r5 while the
    filter meant it to slide sideways round it. Here an omni robot comes up from behind a
    differential one crossing its path: filtered as a point, the differential one was to step
    north out of the way, which its wheels cannot do, and the gap fell to 4 mm. With its axis
    rows the omni robot is the one held back: the 5 cm margin holds (less the few mm one
    50 ms step overshoots), and the differential robot still gets on."""
    pa, nom_a, nom_b = (-0.096, 0.265, 0.014), (0.265, 0.293), (-0.068, 0.384)
    assert _encounter(pa, nom_a, nom_b, axis=False) < 0.01
    end = []
    assert _encounter(pa, nom_a, nom_b, axis=True, out=end) > 0.045
    assert end[0][0, 0] - (5 + pa[0]) > 0.4  # the differential robot drove on east, 4 s


def test_differential_robots_keep_the_margin_in_seeded_encounters():
    rng = np.random.default_rng(11)
    for _ in range(30):
        ang, d = rng.uniform(0, 2 * np.pi), rng.uniform(0.26, 0.5)
        pa = (d * np.cos(ang), d * np.sin(ang), rng.uniform(-np.pi, np.pi))
        nom_a, nom_b = rng.uniform(-0.4, 0.4, 2), rng.uniform(-0.4, 0.4, 2)
        assert _encounter(pa, nom_a, nom_b, axis=True) > 0.04, (pa, nom_a, nom_b)


def _held_barrier(tell_the_filter: bool, gap: float, speed: float) -> float:
    """One guard tick: r1 (omni) caging the crate, held (commanded zero after the filter); r4
    (differential, facing r1) ``gap`` m from it, driving at it at ``speed`` m/s the tick before
    and still asked to. Returns how far r4's own command keeps the pair's barrier,
    2 d.u4 + gamma h (m^2/s): >= 0 kept by r4 alone, < 0 only if r1 moved away, which it will
    not. ``tell_the_filter`` False is the pipeline before: hold applied only after the filter."""
    from controller.config import parse_config
    from controller.mission.guard import SafetyStage
    from controller.mission.types import FleetView, Intent
    from tests.support.config import base_config_dict

    data = base_config_dict()
    data["robots"] = [data["robots"][0], data["robots"][3]]  # r1 omni, r4 differential
    assert [r["kind"] for r in data["robots"]] == ["omni", "diff"]
    cfg = parse_config(data, "<held>")
    stage = SafetyStage(cfg)
    d = 0.2 + gap
    poses = np.array([[5.0, 5.0, 0.0], [5.0 + d, 5.0, np.pi]])  # r4 east of r1, facing it
    stage.v_prev = np.array([[0.0, 0.0], [-speed, 0.0]])
    held = np.array([True, False])
    view = FleetView(0.0, cfg.robot_ids, poses, np.zeros((2, 3)), np.zeros(2, bool),
                     np.ones(2, bool), None, None, None, False)  # fmt: skip
    intent = Intent.of(np.array([[0.0, 0.0], [-speed, 0.0]]), "close_in",
                    hold=held if tell_the_filter else None)  # fmt: skip
    cmd = stage.apply(view, intent).commands
    u4 = np.array([-cmd[1, 0], 0.0])  # facing west: forward is -x
    rel = poses[1, :2] - poses[0, :2]
    h = rel @ rel - (0.2 + cfg.approach.safety_margin) ** 2
    return float(2 * rel @ u4 + stage.filter.gamma * h)


def test_a_held_robot_is_fixed_in_the_filter_so_the_other_keeps_the_barrier_alone():
    """The README lab's second collision: r6 (differential) drove into r2, which was caging the
    crate. A held robot is commanded zero after the filter; the filter did not know it, gave it
    half of the avoiding, and the other robot kept only its half: inside the margin it still
    closed in. Told, the filter leaves every barrier to a held robot to the other one."""
    for gap in (0.04, 0.02, 0.01):
        for speed in (0.1, 0.2, 0.3):
            assert _held_barrier(False, gap, speed) < -1e-3, (gap, speed)  # r4 closes in
            assert _held_barrier(True, gap, speed) >= -1e-6, (gap, speed)


def _pass_by(close: bool) -> tuple[float, float]:
    """r1 fixed (a caging robot), r2 driven at 0.2 m/s past it on a line 3 cm from touching,
    along a wall that leaves no wider way (a robot closing in on its contact in a concave notch,
    the next contact along). Returns the least gap and how far r2 got along its line (m)."""
    r = np.full(2, 0.1)
    flt = SafetyFilter(r, np.full(2, 0.4), BOUNDS, 1, margin=0.05, close_margin=0.02)
    wall = np.array([[3.0, 5.38], [7.0, 5.38], [7.0, 6.0], [3.0, 6.0]])  # r2 keeps y <= 5.23
    p = np.array([[5.0, 5.0], [4.0, 5.23]])
    both = np.ones(2, bool) if close else None
    least = np.inf
    for _ in range(150):  # 6 s at 25 Hz
        res = flt.filter(p, np.array([[0.0, 0.0], [0.2, 0.0]]), [wall],
                         stale=np.array([True, False]), close=both)  # fmt: skip
        p = p + 0.04 * res.velocities
        least = min(least, float(np.linalg.norm(p[1] - p[0]) - 0.2))
    return least, float(p[1, 0] - 4.0)


def test_two_robots_at_the_object_keep_the_capture_clearance_between_them():
    """Contacts in a concave notch lie nearer each other than the safety margin (the arrest
    scenario evade-L: r2 had to pass r5, caging at the notch's inner edge, with the wall 37 cm
    beyond): two robots both at the object keep ``capture.clearance`` (2 cm) between them, so
    the second gets by; any other pair keeps the 5 cm margin and the robot stays behind."""
    least, went = _pass_by(close=True)
    assert 0.02 - 1e-3 <= least < 0.05 and went > 1.1, (least, went)
    least, went = _pass_by(close=False)
    assert least >= 0.05 - 1e-3 and went < 1.0, (least, went)


def test_a_large_fleet_filtered_with_only_the_pairs_that_can_bind_matches_every_pair():
    """60 robots, clustered (pairs in and out of reach), an obstacle, a few axial ones: the
    QP with the pairs that can bind (the default above PRUNE_PAIRS pairs) gives the velocities
    of the QP with all 1 770 pairs, step after step, and keeps the margin in a crowded swap."""
    rng = np.random.default_rng(5)
    n = 60
    centres = rng.uniform(2, 8, (6, 2))
    p = np.zeros((0, 2))
    while len(p) < n:  # in clusters, 0.3 m apart at least (outside each other's margin)
        q = np.clip(centres[rng.integers(0, 6)] + rng.normal(0, 0.6, 2), 0.5, 9.5)
        inside_box = np.all(np.abs(q - 5.0) < 0.5 + 0.2)
        if not inside_box and (len(p) == 0 or np.linalg.norm(p - q, axis=1).min() > 0.3):
            p = np.vstack([p, q])
    goal = rng.uniform(1, 9, (n, 2))
    box = np.array([[4.5, 4.5], [5.5, 4.5], [5.5, 5.5], [4.5, 5.5]])
    axial = np.arange(n) % 5 == 0
    kw = dict(margin=0.05, axial=axial)
    pruned = SafetyFilter(np.full(n, 0.1), np.full(n, 0.4), BOUNDS, 1, **kw)
    full = SafetyFilter(np.full(n, 0.1), np.full(n, 0.4), BOUNDS, 1, prune=False, **kw)
    assert pruned.prune and not full.prune
    dmin, kept = np.inf, []
    for _ in range(60):
        v = goal - p
        s = np.linalg.norm(v, axis=1, keepdims=True)
        u_nom = v / np.maximum(s, 1e-9) * np.minimum(s, 0.4)
        th = np.arctan2(u_nom[:, 1], u_nom[:, 0])
        a = pruned.filter(p, u_nom, [box], headings=th)
        b = full.filter(p, u_nom, [box], headings=th)
        assert a.status == b.status
        assert np.allclose(a.velocities, b.velocities, atol=2e-3), np.abs(
            a.velocities - b.velocities
        ).max()
        kept.append(len(pruned.pi))
        p = p + 0.1 * a.velocities
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        d[np.eye(n, dtype=bool)] = np.inf
        dmin = min(dmin, float(d.min()))
    assert max(kept) < len(full.pi) / 4  # the QP held a fraction of the pairs
    assert dmin >= 0.25 - 5e-3


def test_a_differential_robot_asked_to_go_sideways_turns_one_way_not_back_and_forth():
    """A desired velocity about 90 degrees off a differential robot's axis, jittering across
    90 (estimate noise): each tick on its own picks the nearer end of the axis, so the heading
    error jumps between about +90 and -90 degrees and the robot is told full yaw rate one way,
    then the other (a real-time lab run: r4 commanded +2 / -2 rad/s tick after tick, dithering,
    its filter rejecting its poses). With the end kept from one tick to the next
    (``track_reversible_ends``) it is never told full rate one way right after the other, and
    asked to go somewhere fixed, it turns to it."""
    from controller.mission.tracking import track_reversible_ends

    lim = RobotLimits(np.array([False]), np.full(1, 0.4), np.full(1, 2.0), np.full(1, 1.0))
    dt = 0.05

    def run(kept: bool, relative: bool) -> tuple[int, float]:
        """Full-rate reversals in 60 ticks, and the final heading (rad)."""
        rng = np.random.default_rng(7)
        pose = np.array([[5.0, 5.0, 0.0]])
        backward, wz = None, []
        for _ in range(60):
            # sideways to the robot (what a barrier pushing it off asks) or up in the world
            ang = np.pi / 2 + rng.normal(0.0, np.radians(4.0)) + (pose[0, 2] if relative else 0)
            v = 0.3 * np.array([[np.cos(ang), np.sin(ang)]])
            if kept:
                cmd, backward = track_reversible_ends(pose, v, lim, backward=backward)
            else:
                cmd = track_reversible(pose, v, lim)
            wz.append(cmd[0, 2])
            pose[0, 2] += dt * cmd[0, 2]
        w = np.array(wz)
        return int(
            np.sum((w[:-1] * w[1:] < 0) & (np.minimum(abs(w[:-1]), abs(w[1:])) > 1.5))
        ), pose[0, 2]

    each, _ = run(kept=False, relative=True)
    kept, _ = run(kept=True, relative=True)
    assert kept == 0 and each > 10, (each, kept)
    fixed, heading = run(kept=True, relative=False)
    off = abs((heading - np.pi / 2 + np.pi / 2) % np.pi - np.pi / 2)  # from the axis, either end
    assert fixed == 0 and off < np.radians(8.0), np.degrees(heading)


def test_a_held_robot_inside_its_margin_freezes_no_one():
    """A lab run's re-arrangement: a held robot (fixed at zero) 4 cm from the object, inside
    the 5 cm margin, and two movers just off their old contacts (1 mm from the object). The
    held robot's own barrier could never be kept (its velocity is fixed), the QP was infeasible
    every tick, and every robot inside a margin stopped for good: the movers never left, the
    re-arrangement timed out. Held robots keep no barrier of their own; the movers back off to
    the margin and go on."""
    r = np.full(3, 0.1)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) + 4.0
    flt = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 1, margin=0.05)
    p = np.array([[4.5, 5.14], [3.899, 4.5], [5.101, 4.5]])  # held above; movers left, right
    held = np.array([True, False, False])
    nominal = np.array([[0.0, 0.0], [0.0, -0.3], [0.0, 0.3]])  # movers slide along the faces
    res = flt.filter(p, nominal, [square], stale=held)
    assert not res.stopped.any(), res.status
    assert np.allclose(res.velocities[0], 0.0)  # the held robot stays held
    assert res.velocities[1, 0] < -0.05 and res.velocities[2, 0] > 0.05  # the movers back off
    assert abs(res.velocities[1, 1] + 0.3) < 0.05 and abs(res.velocities[2, 1] - 0.3) < 0.05


def test_a_solve_stopped_at_its_iteration_limit_goes_on_before_anyone_is_stopped(monkeypatch):
    # osqp stopping at max_iter is not an infeasible QP: near the limit the same inputs, down to
    # numpy's SIMD kernels' last bits, ended "relaxed" on one CPU and "every robot stopped" on
    # another. Held to a few iterations, the filter goes on from where osqp stopped and gives
    # the fully converged answer; without going on, it would stop the robots
    from controller.planning import safety

    r = np.full(3, 0.1)
    p = np.array([[5.0, 5.0], [5.32, 5.0], [7.0, 6.0]])
    nom = np.array([[0.3, 0.05], [-0.3, 0.0], [0.2, -0.1]])
    ref = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05).filter(p, nom, [])
    assert ref.status == "solved"
    monkeypatch.setattr(safety, "MAX_ITER", 10)
    monkeypatch.setattr(safety, "MORE_ITER", 400)
    res = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05, warm=False).filter(p, nom, [])
    assert res.status == "solved" and not res.stopped.any()
    assert np.allclose(res.velocities, ref.velocities, atol=2e-3)
    monkeypatch.setattr(safety, "MORE_ITER", 1)  # no going on: the answer would not count
    res = SafetyFilter(r, np.full(3, 0.4), BOUNDS, 0, margin=0.05, warm=False).filter(p, nom, [])
    assert res.status != "solved"
