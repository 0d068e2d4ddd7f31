"""Plots people read: a 64-robot run keeps its legend outside the axes and short, its colours
distinct; time plots mark the phases; the trajectory plot shows the capture points, the route,
robot sizes and starts, and is not clipped to the room."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_hex

from controller import viz
from controller.events import ArrestEvent, CaptureEvent, PhaseEvent, RouteEvent, TransportEvent
from controller.replay.log import RunLog
from tests.support.config import make_config

XS = [0.5 + 1.5 * i for i in range(8)]
YS = [0.5, 1.2, 1.9, 6.5, 7.2, 7.9, 8.6, 9.3]


def fleet(n: int = 64):
    robots = [
        {"id": f"r{k + 1}", "kind": "omni", "radius": 0.1, "start": [XS[k % 8], YS[k // 8], 0.0]}
        for k in range(n)
    ]
    return make_config({"robots": robots})


def synthetic_run(cfg, seconds: float = 10.0) -> RunLog:
    run = RunLog(path=Path("synthetic.mcap"), complete=True, config=cfg, fleet=cfg.fleet.name)
    t = np.arange(0, seconds, 0.05)
    rng = np.random.default_rng(0)
    for r in cfg.robots:
        x = r.start[0] + 0.05 * t
        y = r.start[1] + 0.02 * t
        run.truth[r.id] = [(ti, xi, yi, 0.0) for ti, xi, yi in zip(t, x, y, strict=True)]
        run.estimated[r.id] = [
            (ti, xi + rng.normal(0, 0.005), yi, 0.0) for ti, xi, yi in zip(t, x, y, strict=True)
        ]
    # the object drifts out of the room's east wall: the plot must not clip it
    run.object_truth = [(ti, 12.0 + 0.1 * ti, 3.0, 0.0) for ti in t]
    ev = run.events

    def add(t: float, phase: str, event) -> None:
        ev.append({"t": t, "kind": event.kind, "phase": phase, "data": event.to_dict()})

    add(0.05, "approach", CaptureEvent(
        points=[[0, 0.2], [1, 0.2]], normals=[[-1, 0], [1, 0]], robots=["r1", "r2"],
        objective=1.0, form_closure=True, robots_needed=2, hold_capacity=1.0, reinforced=0,
        pinned=False, wall_contacts=0,
    ))  # fmt: skip
    add(4.0, "close_in", PhaseEvent(phase="close_in", t=4.0))
    add(6.0, "arrested", ArrestEvent(t=6.0, arrival_spread_s=0.5, hold_s=2.0,
                                     hold_displacement_m=0.01, gaps_m=[0.0, 0.0]))  # fmt: skip
    add(7.0, "route", RouteEvent(t=7.0, waypoints=[[12.0, 3.0, 0.0], [9.0, 9.0, 0.0]],
                                 subgoals=[[9.0, 9.0, 0.0]], length_m=6.7, cost_s=7.0,
                                 replans=0))  # fmt: skip
    for k, tt in enumerate((8.0, 8.5, 9.0)):
        plan = {"forces": [[2.0 + k, 0.0]], "first_actions": ["push", "follow"]}
        add(tt, "transport", TransportEvent(t=tt, robots=["r1", "r2"], plan=plan,
                                            relocating={}, plan_age_s=0.0))  # fmt: skip
    return run


@pytest.fixture
def figures(monkeypatch):
    """The figures plot_run draws, kept open to be read."""
    kept = []
    monkeypatch.setattr(viz.plt, "close", lambda fig: kept.append(fig))
    return kept


def test_a_64_robot_run_reads_well(tmp_path, figures):
    cfg = fleet(64)
    files = viz.plot_run(synthetic_run(cfg), tmp_path, {"verdict": []})
    names = [f.name for f in files]
    assert names == ["trajectories.png", "clearance.png", "estimation_error.png", "transport.png"]
    assert all(f.stat().st_size > 10_000 for f in files)
    traj, clear, est, transport = figures
    # the legend says what the marks are (phases, markers), not which robot is which: short,
    # and outside the axes so it hides nothing
    legend = traj.axes[-1].get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    assert len(labels) < 20 and "robot start (disc: its size)" in labels
    assert {"path: approach", "path: close_in", "path: transport"} <= set(labels)
    assert any(lb.startswith("capture points") for lb in labels)
    assert "route (centroid)" in labels
    assert legend.get_bbox_to_anchor().x0 >= traj.axes[-1].get_window_extent().x1 - 1
    # the whole run is in view: the object left the room eastwards, the axes follow it
    x0, x1 = traj.axes[0].get_xlim()
    assert x1 >= 12.0 + 0.1 * 9.95 and x0 <= 0.0
    assert traj.axes[0].get_xlabel() == "x (m)" and traj.axes[0].get_aspect() == 1.0
    # one disc per robot at its start and one at its end, at the robot's size
    from matplotlib.patches import Circle

    discs = [p for p in traj.axes[0].patches if isinstance(p, Circle)]
    assert len(discs) == 2 * 64 and {p.radius for p in discs} == {0.1}
    assert "hardware contract: clean" in traj._suptitle.get_text()
    # estimation error of 64 robots: the fleet's median and worst, not 64 lines
    est_labels = [t.get_text() for t in est.axes[0].get_legend().get_texts()]
    assert len(est_labels) == 3 and est_labels[1] == "median of 64 robots"
    # time plots mark the phases
    words = {t.get_text() for t in clear.axes[0].texts}
    assert {"approach", "close_in", "arrested", "route", "transport"} <= words
    # the pushers' forces over time
    lines = {ln.get_label(): ln for ln in transport.axes[1].get_lines() if ln.get_label()[0] != "_"}
    assert set(lines) == {"r1"} and list(lines["r1"].get_ydata()) == [2.0, 3.0, 4.0]


def test_robot_colours_do_not_repeat():
    for n in (6, 10, 16, 64):
        cols = {to_hex(c) for c in viz.robot_colours(n)}
        assert len(cols) == n


def test_a_few_robots_get_a_line_each(tmp_path, figures):
    cfg = fleet(6)
    viz.plot_run(synthetic_run(cfg), tmp_path)
    est = figures[2]
    labels = [t.get_text() for t in est.axes[0].get_legend().get_texts()]
    assert labels == [f"r{k}" for k in range(1, 7)]
    colours = {to_hex(ln.get_color()) for ln in est.axes[0].get_lines() if ln.get_label() in labels}
    assert len(colours) == 6


def test_a_lab_log_in_epoch_seconds_reads_from_its_start(tmp_path, figures):
    """A daemon's log is stamped on the wall clock: its plots and its replay text count from
    the run's start (the --json keeps the stamps, with t0_s beside them)."""
    from controller.outcome import outcome_table, verdict_line
    from controller.replay.log import log_t0, metrics_of, shifted

    t0 = 1795841900.0
    cfg = fleet(6)
    run = shifted(synthetic_run(cfg), -t0)
    run.stamps["fleet/x/plan/phase"] = [t0, t0 + 9.0]
    assert log_t0(run) == t0
    viz.plot_run(run, tmp_path, {"verdict": []})
    traj, clear = figures[0], figures[1]
    title = traj._suptitle.get_text()
    assert "last phase transport at 8.0 s" in title, title
    assert "1795" not in title
    assert clear.axes[0].get_xlim()[1] < 20  # the time axis from the start, not epoch
    r = metrics_of(run)
    assert r["t0_s"] == t0 and r["arrest_time_s"] > t0  # --json keeps the stamps
    text = verdict_line(r) + "\n" + outcome_table(r)
    assert "1795" not in text and "arrested 6.0 s" in text, text
