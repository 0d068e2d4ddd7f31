"""The contact-force LP (Vass Eq. 1-2 for planar quasi-static pushing): osqp against HiGHS, the
limit surface, infeasible answers with their reasons."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import geometry
from controller.planning.contact_lp import (
    GRAVITY,
    ContactForceLP,
    required_wrench,
    solve_reference,
    twist_for_wrench,
)
from tests.support.transport_cases import L_SHAPE, random_lp

BOX = np.array([[-0.5, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.5, 0.3]])
BACK = (np.array([[-0.5, -0.15], [-0.5, 0.15]]), np.array([[1.0, 0.0], [1.0, 0.0]]))


def check_solution(args: dict, res, tol: float = 1e-6) -> None:
    """The forces make the wanted wrench and respect the bounds and the friction cone."""
    pts, nrm = args["points"], args["normals"]
    tang = np.stack([-nrm[:, 1], nrm[:, 0]], axis=1)
    f = res.normal[:, None] * nrm + res.tangential[:, None] * tang
    wrench = np.array(
        [f[:, 0].sum(), f[:, 1].sum(), np.sum(pts[:, 0] * f[:, 1] - pts[:, 1] * f[:, 0])]
    )
    scale = max(1.0, float(np.abs(args["wrench"]).max()))
    assert np.allclose(wrench, args["wrench"], atol=tol * scale * 10)
    upper = np.where(args["active"], args["max_force"], 0.0)
    assert np.all(res.normal >= -tol * scale) and np.all(res.normal <= upper + tol * scale)
    mu = args["contact_friction"]
    assert np.all(np.abs(res.tangential) <= mu * res.normal + tol * scale)


@pytest.mark.parametrize(
    "n, mu_c, seed", [(4, 0.0, 1), (8, 0.0, 2), (8, 0.3, 3)], ids=["4-frictionless", "8", "8-mu0.3"]
)
def test_osqp_matches_highs_on_random_instances(n, mu_c, seed):
    """>= 200 seeded instances each: same feasibility, objective within 1e-4 relative."""
    rng = np.random.default_rng(seed)
    lp = ContactForceLP(n, friction=mu_c > 0)
    feasible = infeasible = 0
    for _ in range(220):
        args = random_lp(rng, n, mu_c)
        ours = lp.solve(**args)
        ref = solve_reference(**{k: v for k, v in args.items() if k != "length"})
        assert ours.status == ref.status, (ours, ref)
        if ref.feasible:
            feasible += 1
            assert abs(ours.total - ref.total) <= 1e-4 * max(ref.total, 1e-9)
            check_solution(args, ours)
        else:
            infeasible += 1
            assert ours.reason == ref.reason
    assert feasible >= 40 and infeasible >= 40  # both kinds were exercised
    assert lp.solves >= 150  # osqp answered (HiGHS only as the fallback)
    # ADMM crawls on the friction-cone LPs; the rescue proves its iterate optimal or infeasible
    assert lp.fallbacks <= 0.01 * lp.solves


def test_polish_makes_the_answer_exact():
    rng = np.random.default_rng(5)
    lp = ContactForceLP(6, polish=True)
    worst, polished = 0.0, 0
    for _ in range(60):
        args = random_lp(rng, 6)
        ours = lp.solve(**args)
        ref = solve_reference(**{k: v for k, v in args.items() if k != "length"})
        if ours.feasible and ours.solver == "osqp":
            polished += ours.polished
            if ours.polished:
                worst = max(worst, abs(ours.total - ref.total) / ref.total)
    assert polished >= 10
    assert worst < 1e-9


def test_limit_surface_translation_rotation_and_scale():
    m, mu, rbar = 4.0, 0.2, 0.3
    f_max = mu * m * GRAVITY
    w = required_wrench([0.1, 0.0, 0.0], m, mu, rbar)
    assert np.allclose(w, [f_max, 0.0, 0.0])
    w = required_wrench([0.0, 0.0, -0.5], m, mu, rbar)
    assert np.allclose(w, [0.0, 0.0, -f_max * rbar])
    twist = np.array([0.05, -0.02, 0.3])
    w1 = required_wrench(twist, m, mu, rbar)
    w2 = required_wrench(3 * twist, m, mu, rbar)
    assert np.allclose(w1, w2)  # Coulomb friction: only the direction counts
    assert math.isclose((w1[0] ** 2 + w1[1] ** 2) / f_max**2 + w1[2] ** 2 / (f_max * rbar) ** 2, 1)
    direction, moves = twist_for_wrench(w1, m, mu, rbar)
    assert moves
    assert np.allclose(direction / np.linalg.norm(direction), twist / np.linalg.norm(twist))
    _, moves = twist_for_wrench(0.9 * w1, m, mu, rbar)
    assert not moves
    assert not np.any(required_wrench([0.0, 0.0, 0.0], m, mu, rbar))


def test_geometry_mean_radius_is_the_sims():
    pybullet_world = pytest.importorskip("sim_backend.pybullet_world")
    for poly in (L_SHAPE, BOX):
        assert geometry.mean_radius(poly) == pybullet_world.mean_radius(poly)


def test_two_back_pushers_share_a_straight_push():
    lp = ContactForceLP(4)
    w = required_wrench([0.1, 0.0, 0.0], 4.0, 0.2, geometry.mean_radius(BOX))
    res = lp.solve(*BACK, [6.0, 6.0], [True, True], w, 0.0, 0.3)
    assert res.feasible
    assert np.allclose(res.normal, [w[0] / 2, w[0] / 2], atol=1e-4)
    assert math.isclose(res.total, 4.0 * 0.2 * GRAVITY, rel_tol=1e-5)


def test_too_weak_robots_are_infeasible_for_force_limit():
    lp = ContactForceLP(4)
    w = required_wrench([0.1, 0.0, 0.0], 4.0, 0.2, 0.3)  # 7.85 N
    res = lp.solve(*BACK, [3.0, 3.0], [True, True], w, 0.0, 0.3)
    assert res.status == "infeasible" and res.reason == "force_limit"
    assert res.binding == (0, 1)
    assert not np.any(res.normal)
    ok = lp.solve(*BACK, [4.0, 4.0], [True, True], w, 0.0, 0.3)
    assert ok.feasible


def test_no_pusher_on_the_needed_side_is_outside_the_cone():
    lp = ContactForceLP(4)
    w = required_wrench([-0.1, 0.0, 0.0], 4.0, 0.2, 0.3)  # pull backwards: nobody is in front
    res = lp.solve(*BACK, [50.0, 50.0], [True, True], w, 0.0, 0.3)
    assert res.status == "infeasible" and res.reason == "outside_cone"
    # one back pusher alone cannot push straight (its push turns the box)
    w = required_wrench([0.1, 0.0, 0.0], 4.0, 0.2, 0.3)
    res = lp.solve(*BACK, [50.0, 50.0], [True, False], w, 0.0, 0.3)
    assert res.reason == "outside_cone"


def test_passive_robots_push_nothing_and_none_active_is_no_pushers():
    lp = ContactForceLP(4)
    w = required_wrench([0.1, 0.0, 0.0], 4.0, 0.2, 0.3)
    res = lp.solve(*BACK, [6.0, 6.0], [False, False], w, 0.0, 0.3)
    assert res.status == "infeasible" and res.reason == "no_pushers"
    still = lp.solve(*BACK, [6.0, 6.0], [True, True], [0.0, 0.0, 0.0], 0.0, 0.3)
    assert still.feasible and still.total == 0.0


def test_contact_friction_lets_one_pusher_turn_less():
    """With friction one pusher on the back face can also drag the box sideways (its tangential
    force turns the box the way the twist turns it); without friction it cannot."""
    pts = np.array([[-0.5, 0.0]])
    nrm = np.array([[1.0, 0.0]])
    w = required_wrench([0.1, 0.02, -0.5 * 0.02 / 0.3**2], 4.0, 0.2, 0.3)
    no_friction = ContactForceLP(2).solve(pts, nrm, [20.0], [True], w, 0.0, 0.3)
    assert no_friction.reason == "outside_cone"
    with_friction = ContactForceLP(2, friction=True).solve(pts, nrm, [20.0], [True], w, 0.5, 0.3)
    assert with_friction.feasible
    assert abs(with_friction.tangential[0]) <= 0.5 * with_friction.normal[0] + 1e-9


def test_bad_calls_are_errors_not_answers():
    lp = ContactForceLP(2)
    with pytest.raises(ValueError, match="contacts for an LP built for 2"):
        lp.solve(np.zeros((3, 2)), np.ones((3, 2)), [1, 1, 1], [1, 1, 1], [1, 0, 0])
    with pytest.raises(ValueError, match="friction=True"):
        lp.solve(*BACK, [6.0, 6.0], [True, True], [1.0, 0, 0], 0.3)
    with pytest.raises(ValueError, match="max_contacts"):
        ContactForceLP(0)


def test_rescue_keeps_friction_lps_off_highs():
    """With contact friction 0.3 osqp alone stops short on about a sixth of the LPs (they went
    to HiGHS); the rescue proves those answers (same status and objective as HiGHS) instead."""
    rng = np.random.default_rng(7)
    problems = [random_lp(rng, 8, 0.3) for _ in range(150)]
    plain = ContactForceLP(8, friction=True, rescue=False)
    ours = ContactForceLP(8, friction=True)
    for args in problems:
        plain.solve(**args)
        res = ours.solve(**args)
        ref = solve_reference(**{k: v for k, v in args.items() if k != "length"})
        assert res.status == ref.status
        if ref.feasible:
            assert abs(res.total - ref.total) <= 1e-4 * max(ref.total, 1e-9)
            check_solution(args, res)
    assert plain.fallbacks >= 0.05 * plain.solves
    assert ours.rescued >= 0.05 * ours.solves
    assert ours.fallbacks <= 0.01 * ours.solves
