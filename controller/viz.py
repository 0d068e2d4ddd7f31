"""Every figure of the project (the only matplotlib importer): run plots, capture and route
plans. Figures are written as PNG files with the Agg backend (no display needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from controller import geometry  # noqa: E402
from controller.replay import metrics  # noqa: E402
from controller.replay.log import RunLog, _track  # noqa: E402


def plot_run(run: RunLog, out_dir: str | Path) -> list[Path]:
    """PNG plots of a run: trajectories (with obstacles and object outlines), robot clearance
    and estimation error over time. Returns the files written."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = run.config
    ids = list(cfg.robot_ids) if cfg else sorted(set(run.measured) | set(run.truth))
    src = run.truth if run.truth else (run.estimated or run.measured)
    written = [_plot_trajectories(run, ids, src, out / "trajectories.png")]
    if cfg is not None and len(ids) > 1:
        written += _plot_clearance(run, ids, src, out / "clearance.png")
    if run.truth and run.estimated:
        written.append(_plot_estimation_error(run, ids, out / "estimation_error.png"))
    return written


def _plot_trajectories(run: RunLog, ids: list[str], src: dict, path: Path) -> Path:
    cfg = run.config
    fig, ax = plt.subplots(figsize=(7, 7))
    if cfg is not None:
        b = cfg.bounds_array()
        ax.set_xlim(b[0, 0], b[1, 0])
        ax.set_ylim(b[0, 1], b[1, 1])
        for poly in cfg.obstacle_polygons():
            ax.fill(*np.asarray(poly).T, color="0.6")
    for rid in ids:
        tr = _track(src.get(rid, []))
        if len(tr):
            (line,) = ax.plot(tr.pose[:, 0], tr.pose[:, 1], lw=1, label=rid)
            ax.plot(*tr.pose[-1, :2], "o", ms=4, color=line.get_color())
    obj = _track(run.object_truth or run.object_estimated or run.object_measured)
    if len(obj):
        ax.plot(obj.pose[:, 0], obj.pose[:, 1], "k--", lw=1, label="object")
        if cfg is not None:
            poly = cfg.object_polygon()
            for k in np.linspace(0, len(obj) - 1, 6).astype(int):
                ax.fill(*geometry.transform(poly, obj.pose[k]).T, fill=False, ec="k", lw=0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(f"{run.path.name}: trajectories")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_clearance(run: RunLog, ids: list[str], src: dict, path: Path) -> list[Path]:
    cfg = run.config
    assert cfg is not None
    tracks = [_track(src.get(rid, [])) for rid in ids]
    have = [(tr, cfg.robot(r).radius) for r, tr in zip(ids, tracks, strict=True) if len(tr)]
    tracks_h = [tr for tr, _ in have]
    grid = metrics.common_grid(tracks_h)
    if not len(grid) or len(tracks_h) < 2:
        return []
    fig, ax = plt.subplots(figsize=(7, 3))
    ax.plot(grid, metrics.clearance_series(tracks_h, [r for _, r in have], grid))
    ax.axhline(0, color="r", lw=0.8)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("min robot gap (m)")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return [path]


def _plot_estimation_error(run: RunLog, ids: list[str], path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7, 3))
    for rid in ids:
        est, truth = _track(run.estimated.get(rid, [])), _track(run.truth.get(rid, []))
        if len(est) and len(truth) > 1:
            err = np.linalg.norm(est.pose[:, :2] - truth.at(est.t)[:, :2], axis=1)
            ax.plot(est.t, err * 100, lw=0.8, label=rid)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("estimate error (cm)")
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_capture_plan(path: str, polygon, plan) -> None:
    """The capture plan: candidates, chosen points, robots and push normals; GA history."""
    poly = geometry.ensure_ccw(polygon)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 5))
    ax.fill(poly[:, 0], poly[:, 1], color="0.85", ec="k")
    ax.plot(plan.candidates[:, 0], plan.candidates[:, 1], ".", color="0.5", ms=4)
    c = geometry.centroid(poly)
    ax.plot(*c, "k+")
    for p, n in zip(plan.points, plan.push_normals, strict=True):
        ax.add_patch(plt.Circle(p + 0.1 * n, 0.1, fill=False, color="tab:blue"))
        ax.annotate("", xy=p, xytext=p + 0.25 * n, arrowprops={"arrowstyle": "->", "color": "r"})
    ax.set_aspect("equal")
    ax.set_title(f"{plan.robots_needed} robots, closure {plan.form_closure}")
    h = np.asarray(plan.history)
    ax2.plot(np.where(h > -1e19, h, np.nan))
    ax2.set_xlabel("generation")
    ax2.set_ylabel("best objective")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_route(path: str, bounds, obstacles, footprint, start, goal, res) -> None:
    """The object route: room, obstacles, start and goal footprints, waypoints and subgoals."""
    fig, ax = plt.subplots(figsize=(7, 7))
    b = np.asarray(bounds, dtype=float).reshape(2, 2)
    ax.plot(b[[0, 1, 1, 0, 0], 0], b[[0, 0, 1, 1, 0], 1], "k-", lw=1)
    for o in obstacles:
        o = np.asarray(o)
        ax.fill(o[:, 0], o[:, 1], color="0.4")
    for pose, colour in ((start, "tab:green"), (goal, "tab:red")):
        q = geometry.transform(footprint, pose)
        ax.fill(q[:, 0], q[:, 1], color=colour, alpha=0.5)
    if res.ok:
        wp = res.waypoints
        ax.plot(wp[:, 0], wp[:, 1], "-", color="tab:blue", lw=1.5, label="route")
        for sg in res.subgoals:
            q = geometry.transform(footprint, sg)
            ax.plot(
                np.r_[q[:, 0], q[0, 0]], np.r_[q[:, 1], q[0, 1]], "-", color="tab:orange", lw=0.8
            )
        ax.legend(loc="upper right")
    ax.set_aspect("equal")
    ax.set_title(f"{res.status}: {res.heuristic}, wg={res.wg}, wh={res.wh}, N_open={res.expanded}")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
