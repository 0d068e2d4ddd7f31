"""Braces for a fast object (issue 34 item 10, ``controller/mission/brace.py``): the brace set
stops a push along the object's motion and either side of it, from the leading faces; its
robots are ahead of the object and meet it together; the capture set is planned again with the
braces fixed in it, clear of them; nothing changes for an object slower than
``approach.brace_share`` of the robots' speed or with braces off."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import linprog

from controller import geometry
from controller.mission import brace
from controller.mission.brace import Braces, brace_nodes, braced_capture, rebraced_capture
from controller.mission.types import FleetView
from controller.planning.capture import candidate_nodes
from controller.planning.capture_set import plan_capture_set
from controller.planning.hold import contact_wrenches
from tests.support.arrest_scenarios import OPEN, OPEN_STARTS, RECT, ArrestScenario, arrest_config

CRATE = np.array(RECT, float)


def _crate_nodes(radius: float = 0.15):
    cand = candidate_nodes(CRATE, radius, 0.05, 1e-3)
    centres = cand.points + radius * cand.normals
    conflict = np.linalg.norm(centres[:, None] - centres[None], axis=-1) < 2 * radius + 0.05
    np.fill_diagonal(conflict, False)
    return cand.points, cand.normals, conflict


def _resists(points, normals, push: np.ndarray) -> bool:
    """Whether frictionless contacts at ``points`` can cancel ``push`` (unit, object frame) with
    no turn."""
    w = contact_wrenches(points, normals, geometry.centroid(CRATE))
    res = linprog(np.ones(len(points)), A_eq=w, b_eq=np.r_[-push, 0.0], method="highs")
    return res.status == 0


@pytest.mark.parametrize("heading", [0.0, 0.1, 0.2, 0.3, -0.6, 1.2, np.pi])
def test_the_braces_stop_the_push_and_either_side_of_it_from_ahead(heading):
    pts, nrm, conflict = _crate_nodes()
    d = np.array([np.cos(heading), np.sin(heading)])
    pick = brace_nodes(pts, nrm, geometry.centroid(CRATE), d, conflict)
    assert 2 <= len(pick) <= brace.MAX_BRACES
    assert (nrm[pick] @ d > -np.sin(brace.SPREAD) - 1e-9).all()  # none on a trailing face
    assert (nrm[pick] @ d > 0.5).any()  # one at least on a face it moves toward
    assert not conflict[np.ix_(pick, pick)].any()  # robot discs clear of each other
    for dev in (0.0, -brace.SPREAD, brace.SPREAD):
        push = np.array([np.cos(heading + dev), np.sin(heading + dev)])
        assert _resists(pts[pick], nrm[pick], push), dev


def test_no_braces_where_one_contact_is_all_there_is():
    pts, nrm, _ = _crate_nodes()
    east = np.flatnonzero(nrm[:, 0] > 0.9)[:1]  # one node on the leading face, no other
    got = brace_nodes(pts[east], nrm[east], geometry.centroid(CRATE), np.array([1.0, 0.0]),
                      np.zeros((1, 1), bool))  # fmt: skip
    assert len(got) == 0  # a single frictionless brace lets the object slide past


def _fast_case(speed: float = 0.45, share: float = 0.6):
    sc = ArrestScenario(
        "brace-unit", RECT, (5.0, 5.0, 0.0), {"kind": "line", "speed": speed, "heading": 0.3},
        kinds="oooooo", max_speed=0.5, seed=21, room=OPEN,
        robot_starts=tuple((*p, 0.0) for p in OPEN_STARTS),
        patch={"approach": {"brace_share": share}},
    )  # fmt: skip
    cfg = arrest_config(sc)
    capture = plan_capture_set(cfg, np.random.default_rng(cfg.capture.seed))
    n = len(cfg.robots)
    poses = np.array([[x, y, 0.0] for x, y in OPEN_STARTS])
    h = 0.3
    view = FleetView(
        2.0, cfg.robot_ids, poses, np.zeros((n, 3)), np.zeros(n, bool), np.ones(n, bool),
        np.array([5.9, 5.3, 0.0]), np.array([speed * np.cos(h), speed * np.sin(h), 0.0]),
        None, False,
    )  # fmt: skip
    return cfg, capture, view


def test_the_braced_capture_keeps_the_braces_robots_ahead_and_the_set_clear_of_them():
    cfg, capture, view = _fast_case()
    available = np.ones(len(cfg.robots), bool)
    got = braced_capture(cfg, capture, view, available)
    assert got is not None
    new, braces, assignment = got
    assert 2 <= braces.sum() <= brace.MAX_BRACES
    assert len(assignment) == len(new.points) == len(braces)
    assert len(set(assignment.tolist())) == len(assignment)  # one point per robot
    assert new.hold_capacity >= 1.0  # the whole set holds, the braces force-limited too
    d = view.object_velocity[:2] / np.linalg.norm(view.object_velocity[:2])
    mid = geometry.transform(geometry.centroid(CRATE)[None], view.object_pose)[0]
    ahead = (view.poses[assignment[braces], :2] - mid) @ d
    assert (ahead > 0).all()  # only robots the object runs toward brace
    # no robot's contact lies where its disc would overlap a brace's
    r = cfg.max_robot_radius
    centres = new.points + r * new.normals
    gap = np.linalg.norm(centres[braces][:, None] - centres[~braces][None], axis=-1)
    assert (gap >= 2 * r + max(cfg.capture.clearance, cfg.approach.safety_margin)).all()


def test_no_braces_for_a_slow_object_or_with_braces_off():
    cfg, capture, view = _fast_case(share=1.0)  # the object at 0.45 is slower than 0.5 m/s
    available = np.ones(len(cfg.robots), bool)
    assert braced_capture(cfg, capture, view, available) is None
    cfg, capture, view = _fast_case(share=0.0)
    assert braced_capture(cfg, capture, view, available) is None


def test_no_brace_for_robots_all_behind_the_object():
    cfg, capture, view = _fast_case()
    behind = view.poses.copy()
    behind[:, 0] = np.linspace(0.5, 3.0, len(behind))  # every robot west of the object at x 5.9
    got = braced_capture(cfg, capture, dataclasses.replace(view, poses=behind),
                         np.ones(len(cfg.robots), bool))  # fmt: skip
    assert got is None


def test_the_braces_meet_the_object_together_and_wait_once_it_is_near():
    b = Braces(3)
    b.on[:] = [True, True, False]
    tgt = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 0.0]])
    vel = np.array([[0.5, 0.0], [0.5, 0.0], [0.5, 0.0]])
    none = np.zeros(3, bool)
    goal = b.meet(tgt, vel, np.array([4.0, 6.0, 3.0]), none)
    assert np.allclose(goal[:2, 0], 1.0 + 0.5 * 6.0)  # both at the later meeting: side by side
    assert np.allclose(goal[2], [1.5, 0.0])  # the others keep their own time
    assert np.isnan(b.at).all()  # far yet: the meeting point follows the prediction
    near = b.meet(tgt, vel, np.array([1.0, 1.5, 3.0]), none)
    moved = b.meet(tgt + 0.3, vel, np.array([1.0, 1.5, 3.0]), none)
    assert np.allclose(moved[:2], near[:2])  # fixed: a brace waits, it does not adjust
    again = b.meet(tgt + 0.3, vel, np.array([0.0, 0.0, 3.0]), np.array([True, False, False]))
    assert np.allclose(again[0], tgt[0] + 0.3)  # released: it aims at the contact again
    assert np.allclose(again[1], near[1])


def test_masks_let_braces_touch_and_hold_still_only_those_touching():
    b = Braces(3)
    b.on[:] = [True, False, True]
    touch, still = b.masks(5, np.array([4, 0, 2]), np.array([0.01, 0.0, 0.2]), 0.06)
    assert touch.tolist() == [False, False, True, False, True]
    assert still.tolist() == [False, False, False, False, True]
    assert Braces(2).masks(3, np.array([0, 1]), np.zeros(2), 0.06) == (None, None)


def test_a_robot_stuck_while_others_brace_gets_a_set_around_the_braces_without_its_nodes():
    cfg, capture, view = _fast_case()
    available = np.ones(len(cfg.robots), bool)
    new, braces, assignment = braced_capture(cfg, capture, view, available)
    stuck = int(np.flatnonzero(~braces)[0])  # a point whose robot could not get there
    node = int(new.chosen[stuck])
    near = np.linalg.norm(new.candidates - new.candidates[node], axis=1) < 0.15
    exclude = frozenset(int(i) for i in np.flatnonzero(near))
    got = rebraced_capture(cfg, new, view, braces, assignment, available, exclude)
    assert got is not None
    again, braces2, assignment2 = got
    assert not exclude & set(again.chosen.tolist())  # none of the nodes it could not reach
    kept = {int(n): int(r) for n, r in zip(new.chosen[braces], assignment[braces], strict=True)}
    now = {int(n): int(r) for n, r in zip(again.chosen[braces2], assignment2[braces2], strict=True)}
    assert now == kept  # the braces and their robots stay as they are
    assert len(set(assignment2.tolist())) == len(assignment2)
