"""Every figure of the project (the only matplotlib importer): run plots, capture and route
plans. Figures are written as PNG files with the Agg backend (no display needed)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from controller import geometry  # noqa: E402
from controller.events import CaptureEvent, RouteEvent, TransportEvent  # noqa: E402
from controller.replay import metrics  # noqa: E402
from controller.replay.log import (  # noqa: E402
    RunLog,
    events_of,
    log_t0,
    phases_of,
    shifted,
    track,
    typed_events,
)
from controller.scene.builder import PHASE_COLORS as SCENE_PHASE_COLORS  # noqa: E402

PHASE_COLORS = {k: v[:3] for k, v in SCENE_PHASE_COLORS.items()}  # as in the Foxglove scene
OTHER_PHASE = (0.4, 0.4, 0.4)
MANY = 12  # robots: more than this and time plots show the fleet's median and worst, not each


def plot_run(run: RunLog, out_dir: str | Path, figures: dict | None = None) -> list[Path]:
    """PNG plots of a run. Returns the files written:

    - ``trajectories.png``: the room and obstacles, robot paths coloured by phase with start
      markers and the robots' discs (true size) at start and end, the object's outline at
      several times, its start and goal, the capture points with their push normals, the route;
    - ``clearance.png``: the smallest robot-robot gap and robot-object gap over time;
    - ``estimation_error.png``: each robot's estimate error against ground truth (dry runs;
      the fleet's median and worst beyond 12 robots);
    - ``transport.png`` (a run that transported): the object's lateral deviation from its route
      and each pusher's contact force over time.

    Time plots mark the phase boundaries. Axes are in metres and seconds, times from the run's
    start (a lab log's epoch stamps less its first one). ``figures`` (the replay's metrics)
    puts the verdict in the title."""
    run = shifted(run, log_t0(run))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = run.config
    ids = list(cfg.robot_ids) if cfg else sorted(set(run.measured) | set(run.truth))
    src = run.truth if run.truth else (run.estimated or run.measured)
    phases = phases_of(run)
    written = [_plot_trajectories(run, ids, src, phases, out / "trajectories.png", figures)]
    if cfg is not None and len(ids) > 1:
        written += _plot_clearance(run, ids, src, phases, out / "clearance.png")
    if run.truth and run.estimated:
        written.append(_plot_estimation_error(run, ids, phases, out / "estimation_error.png"))
    if cfg is not None and events_of(run, "transport"):
        written.append(_plot_transport(run, phases, out / "transport.png"))
    return written


def _object_track(run: RunLog) -> metrics.Track:
    return track(run.object_truth or run.object_estimated or run.object_measured)


def _phase_colour(name: str) -> tuple[float, float, float]:
    return PHASE_COLORS.get(name, OTHER_PHASE)


def _paths_by_phase(ax, tracks: dict[str, metrics.Track], phases: list[dict]) -> None:
    """Each robot's path, its segments coloured by the phase they were driven in."""
    from matplotlib.collections import LineCollection

    starts = [p["t"] for p in phases]
    names = [p["phase"] for p in phases]
    for tr in tracks.values():
        if len(tr) < 2:
            continue
        xy = tr.pose[:, :2]
        segs = np.stack([xy[:-1], xy[1:]], axis=1)
        k = metrics.phase_index(tr.t[:-1], starts)
        cols = [_phase_colour(names[i]) if i >= 0 else OTHER_PHASE for i in k]
        ax.add_collection(LineCollection(segs, colors=cols, linewidths=1.2, zorder=3))


def _robot_discs(ax, run: RunLog, tracks: dict[str, metrics.Track], many: bool) -> None:
    """Start (hollow disc, marker, id) and end (filled disc) of every robot, at its true size."""
    from matplotlib.patches import Circle

    cfg = run.config
    for rid, tr in tracks.items():
        if not len(tr):
            continue
        r = cfg.robot(rid).radius if cfg else 0.1
        (x0, y0), (x1, y1) = tr.pose[0, :2], tr.pose[-1, :2]
        ax.add_patch(Circle((x0, y0), r, fill=False, ec="0.3", lw=0.8, zorder=4))
        ax.plot(x0, y0, marker="^", color="0.2", ms=3, zorder=5)
        ax.add_patch(Circle((x1, y1), r, color="0.15", alpha=0.55, zorder=4))
        ax.annotate(
            rid, (x0, y0), xytext=(3, 3), textcoords="offset points", fontsize=5 if many else 7
        )


def _object_outlines(ax, run: RunLog, poly: np.ndarray, obj: metrics.Track) -> None:
    """The object at its start, at a few times along the run (labelled), and its goal."""
    cfg = run.config
    ax.fill(*geometry.transform(poly, cfg.object.start).T, color="tab:green", alpha=0.15)
    if cfg.object.goal is not None:
        g = geometry.transform(poly, cfg.object.goal)
        ax.fill(*g.T, fill=False, ec="tab:green", lw=1.5, ls="--", zorder=2)
        ax.annotate("goal", geometry.centroid(g), ha="center", fontsize=8, color="tab:green")
    if not len(obj):
        return
    ax.plot(obj.pose[:, 0], obj.pose[:, 1], color="0.35", lw=0.8, ls=":", zorder=2)
    for k in np.unique(np.linspace(0, len(obj) - 1, 6).astype(int)):
        q = geometry.transform(poly, obj.pose[k])
        ax.fill(*q.T, fill=False, ec="k", lw=0.8, alpha=0.4 + 0.6 * k / max(len(obj) - 1, 1))
        c = geometry.centroid(q)
        ax.annotate(f"{obj.t[k]:.0f} s", c, ha="center", va="center", fontsize=6, color="0.25")


def _capture_points(ax, run: RunLog, obj: metrics.Track) -> str | None:
    """The capture points and push normals, placed with the object at the arrest (or where it
    was when the fleet last closed in); the label of the legend entry."""
    caps = typed_events(run, CaptureEvent)
    if not caps or not len(obj):
        return None
    cap = caps[-1][1]
    pts = np.asarray(cap.points, float).reshape(-1, 2)
    nrm = np.asarray(cap.normals, float).reshape(-1, 2)
    if not len(pts):
        return None
    arrests = events_of(run, "arrest")
    when = arrests[0]["t"] if arrests else float(obj.t[-1])
    pose = obj.at(when)
    w = geometry.transform(pts, pose)
    ax.plot(w[:, 0], w[:, 1], "x", color="tab:cyan", ms=6, mew=1.5, zorder=6)
    if len(nrm) == len(pts):
        n = nrm @ geometry.rot(pose[2]).T
        ax.quiver(
            *(w + 0.3 * n).T, *(-0.25 * n).T, angles="xy", scale_units="xy", scale=1,
            color="tab:cyan", width=0.004, zorder=6,
        )  # fmt: skip
    return f"capture points (object at t={when:.1f} s)"


def _route(ax, run: RunLog, poly: np.ndarray) -> bool:
    routes = typed_events(run, RouteEvent)
    if not routes:
        return False
    route = routes[-1][1]
    wp = np.asarray(route.waypoints, float).reshape(-1, 3)
    c = geometry.centroid(poly)
    cw = np.array([geometry.transform(c[None], q)[0] for q in wp]).reshape(-1, 2)
    ax.plot(cw[:, 0], cw[:, 1], "-", color="tab:purple", lw=1.8, alpha=0.8, zorder=2)
    for sg in np.asarray(route.subgoals, float).reshape(-1, 3):
        q = geometry.transform(poly, sg)
        ax.fill(*q.T, fill=False, ec="tab:purple", lw=0.6, ls="--", zorder=2)
    return True


def _limits(ax, cfg, tracks: dict[str, metrics.Track], obj: metrics.Track) -> None:
    """The room and everything that moved, with a margin: nothing clipped."""
    pts = [tr.pose[:, :2] for tr in tracks.values() if len(tr)]
    if len(obj):
        pts.append(obj.pose[:, :2])
    if cfg is not None:
        pts.append(cfg.bounds_array())
    allp = np.vstack(pts) if pts else np.zeros((1, 2))
    lo, hi = allp.min(axis=0) - 0.5, allp.max(axis=0) + 0.5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def _draw_scene(ax, run: RunLog, ids: list[str], tracks, obj, phases, legend: bool) -> list:
    """Room, obstacles, object, plan and robot paths on one axes; the legend handles."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    cfg = run.config
    handles: list = []
    if cfg is not None:
        b = cfg.bounds_array()
        ax.plot(b[[0, 1, 1, 0, 0], 0], b[[0, 0, 1, 1, 0], 1], "k-", lw=1.5)
        for poly in cfg.obstacle_polygons():
            ax.fill(*np.asarray(poly).T, color="0.6", zorder=1)
        handles.append(Patch(color="0.6", label="obstacle"))
        poly = geometry.ensure_ccw(cfg.object_polygon())
        _object_outlines(ax, run, poly, obj)
        handles.append(Patch(fill=False, ec="k", label="object at t (s)"))
        handles.append(Patch(color="tab:green", alpha=0.15, label="object at the start"))
        if cfg.object.goal is not None:
            handles.append(Patch(fill=False, ec="tab:green", ls="--", label="goal"))
        label = _capture_points(ax, run, obj)
        if label:
            handles.append(Line2D([], [], ls="", marker="x", color="tab:cyan", label=label))
        if _route(ax, run, poly):
            handles.append(Line2D([], [], color="tab:purple", lw=1.8, label="route (centroid)"))
    _paths_by_phase(ax, tracks, phases)
    _robot_discs(ax, run, tracks, many=len(ids) > MANY)
    seen: list[str] = []
    for p in phases:
        if p["phase"] not in seen:
            seen.append(p["phase"])
    handles += [Line2D([], [], color=_phase_colour(ph), lw=2, label=f"path: {ph}") for ph in seen]
    handles += [
        Line2D([], [], ls="", marker="^", color="0.2", label="robot start (disc: its size)"),
        Patch(color="0.15", alpha=0.55, label="robot at the end"),
    ]
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.2)
    return handles


def _zoom_box(run: RunLog, obj: metrics.Track, tracks) -> np.ndarray | None:
    """Where the action is (the object's path and the robots' ends, with a margin), when it is
    much smaller than the room: [[xmin, ymin], [xmax, ymax]]."""
    cfg = run.config
    if cfg is None or not len(obj):
        return None
    pts = [obj.pose[:, :2]] + [tr.pose[-1:, :2] for tr in tracks.values() if len(tr)]
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0) - 1.0, allp.max(axis=0) + 1.0
    side = float(max(hi - lo))
    mid = (lo + hi) / 2
    room = cfg.bounds_array()
    if side > 0.5 * float(max(room[1] - room[0])):
        return None
    return np.array([mid - side / 2, mid + side / 2])


def _plot_trajectories(
    run: RunLog, ids: list[str], src: dict, phases, path: Path, figures: dict | None
) -> Path:
    cfg = run.config
    tracks = {rid: track(src.get(rid, [])) for rid in ids}
    obj = _object_track(run)
    zoom = _zoom_box(run, obj, tracks)
    if zoom is None:
        fig, ax = plt.subplots(figsize=(10, 8))
        axes = [ax]
    else:
        fig, axes = plt.subplots(1, 2, figsize=(16, 7.5), width_ratios=[1, 1])
    for k, ax in enumerate(axes):
        handles = _draw_scene(ax, run, ids, tracks, obj, phases, legend=k == 0)
    _limits(axes[0], cfg, tracks, obj)
    if zoom is not None:
        axes[1].set_xlim(zoom[0, 0], zoom[1, 0])
        axes[1].set_ylim(zoom[0, 1], zoom[1, 1])
        axes[1].set_title("where the object was (zoom)", fontsize=9)
        r = zoom
        axes[0].plot(r[[0, 1, 1, 0, 0], 0], r[[0, 0, 1, 1, 0], 1], ":", color="0.4", lw=0.8)
    # outside the axes: the legend never hides the action, whatever the number of robots
    axes[-1].legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(_title(run, len(ids), phases, figures), fontsize=10)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _title(run: RunLog, n: int, phases, figures: dict | None) -> str:
    words = f"{run.path.name}: {n} robots"
    if phases:
        words += f", last phase {phases[-1]['phase']} at {phases[-1]['t']:.1f} s"
    if figures is not None and figures.get("verdict") is not None:
        v = figures["verdict"]
        words += ", hardware contract: " + (", ".join(f["reason"] for f in v) if v else "clean")
    return words


def _mark_phases(ax, phases: list[dict], t_end: float | None = None, names: bool = True) -> None:
    """Phase boundaries as vertical lines and shaded spans, the phase names along the top
    (names close together are staggered upwards)."""
    times = [p["t"] for p in phases] + ([t_end] if t_end is not None else [])
    span = (max(times) - min(times)) if times else 0.0
    last, level = -math.inf, 0
    for k, p in enumerate(phases):
        col = _phase_colour(p["phase"])
        ax.axvline(p["t"], color=col, lw=0.8, alpha=0.8)
        nxt = phases[k + 1]["t"] if k + 1 < len(phases) else t_end
        if nxt is not None:
            ax.axvspan(p["t"], nxt, color=col, alpha=0.06, lw=0)
        if names:
            level = (level + 1) % 4 if p["t"] - last < 0.06 * span else 0
            last = p["t"]
            ax.text(
                p["t"], 1.01 + 0.07 * level, p["phase"], transform=ax.get_xaxis_transform(),
                fontsize=6, color=col, ha="left", va="bottom",
            )  # fmt: skip


def _plot_clearance(run: RunLog, ids: list[str], src: dict, phases, path: Path) -> list[Path]:
    cfg = run.config
    assert cfg is not None
    have = [(track(src.get(r, [])), cfg.robot(r).radius) for r in ids]
    have = [(tr, r) for tr, r in have if len(tr)]
    tracks_h = [tr for tr, _ in have]
    radii = np.array([r for _, r in have])
    grid = metrics.common_grid(tracks_h)
    if not len(grid) or len(tracks_h) < 2:
        return []
    fig, ax = plt.subplots(figsize=(9, 3.4))
    ax.plot(grid, metrics.clearance_series(tracks_h, radii, grid), label="robot-robot gap")
    obj = _object_track(run)
    if len(obj) > 1:
        poly = geometry.ensure_ccw(cfg.object_polygon())
        opose = obj.at(grid)
        xy = np.stack([tr.at(grid)[:, :2] for tr in tracks_h], axis=1)
        gap = [
            float(np.min(geometry.polygon_signed_distance(
                geometry.inverse_transform(xy[k], opose[k]), poly) - radii))
            for k in range(len(grid))
        ]  # fmt: skip
        ax.plot(grid, gap, label="robot-object gap", color="tab:orange")
    ax.axhline(0, color="r", lw=0.8)
    _mark_phases(ax, phases, float(grid[-1]))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("smallest gap (m)")
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.2)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return [path]


def robot_colours(n: int) -> list:
    """``n`` distinguishable colours (no repeat after 10, unlike the default cycle)."""
    if n <= 10:
        return [plt.get_cmap("tab10")(i) for i in range(n)]
    if n <= 20:
        return [plt.get_cmap("tab20")(i) for i in range(n)]
    return [plt.get_cmap("turbo")(x) for x in np.linspace(0.05, 0.95, n)]


def _plot_estimation_error(run: RunLog, ids: list[str], phases, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 3.4))
    series = {}
    for rid in ids:
        est, truth = track(run.estimated.get(rid, [])), track(run.truth.get(rid, []))
        if len(est) and len(truth) > 1:
            series[rid] = (est.t, np.linalg.norm(est.pose[:, :2] - truth.at(est.t)[:, :2], axis=1))
    if len(series) > MANY:  # the fleet, not 64 tangled lines
        grid = max((t for t, _ in series.values()), key=len)
        errs = np.array([np.interp(grid, t, e) for t, e in series.values()]) * 100
        ax.fill_between(grid, errs.min(axis=0), errs.max(axis=0), alpha=0.2, label="min-max")
        ax.plot(grid, np.median(errs, axis=0), lw=1, label=f"median of {len(series)} robots")
        ax.plot(grid, errs.max(axis=0), lw=0.6, color="tab:red", label="worst robot")
    else:
        for (rid, (t, e)), col in zip(series.items(), robot_colours(len(series)), strict=True):
            ax.plot(t, e * 100, lw=0.8, label=rid, color=col)
    t_end = max((float(t[-1]) for t, _ in series.values()), default=None)
    _mark_phases(ax, phases, t_end)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("estimate error (cm)")
    ax.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(alpha=0.2)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _plot_transport(run: RunLog, phases, path: Path) -> Path:
    """Lateral deviation of the object from its route, and the contact forces of the pushers."""
    cfg = run.config
    poly = geometry.ensure_ccw(cfg.object_polygon())
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    obj = _object_track(run)
    routes = typed_events(run, RouteEvent)
    if routes and len(obj):
        t0 = routes[0][0]
        c = geometry.centroid(poly)
        keep = obj.t >= t0
        cent = np.array([geometry.transform(c[None], q)[0] for q in obj.pose[keep]]).reshape(-1, 2)
        # each sample against the route in force at its time (a re-plan replaces it)
        starts = [t for t, _ in routes]
        which = metrics.phase_index(obj.t[keep], starts)
        dev = np.full(len(cent), np.nan)
        for k, (_, r) in enumerate(routes):
            wp = np.asarray(r.waypoints, float).reshape(-1, 3)
            cw = np.array([geometry.transform(c[None], q)[0] for q in wp]).reshape(-1, 2)
            sel = which == k
            if sel.any() and len(cw):
                dev[sel] = metrics.lateral_deviation(cent[sel], cw)
        ax1.plot(obj.t[keep], dev, color="tab:purple")
        for t, _ in routes[1:]:
            ax1.axvline(t, color="tab:purple", ls="--", lw=0.8)
    ax1.set_ylabel("object off its route (m)")
    caps = typed_events(run, CaptureEvent)
    forces: dict[str, list[tuple[float, float]]] = {}
    for t, plan in typed_events(run, TransportEvent):
        ids = plan.robots or (caps[-1][1].robots if caps else [])
        first = (plan.forces or [[]])[0] or []
        for rid, f in zip(ids, first, strict=False):
            forces.setdefault(rid, []).append((t, float(f or 0.0)))
    for (rid, rows), col in zip(sorted(forces.items()), robot_colours(len(forces)), strict=True):
        a = np.asarray(rows)
        if np.any(a[:, 1] > 0):
            ax2.step(a[:, 0], a[:, 1], where="post", lw=1, label=rid, color=col)
    ax2.set_ylabel("contact force (N)")
    ax2.set_xlabel("t (s)")
    if ax2.get_legend_handles_labels()[0]:
        ax2.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    else:
        ax2.text(0.5, 0.5, "no pushing force planned", transform=ax2.transAxes, ha="center")
    t_end = float(obj.t[-1]) if len(obj) else None
    for ax in (ax1, ax2):
        _mark_phases(ax, phases, t_end, names=ax is ax1)
        ax.grid(alpha=0.2)
    fig.suptitle(
        "Transport: the object's centroid off its route; each pusher's planned normal force "
        "(first interval of each local plan)",
        fontsize=9,
        y=1.02,
    )
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
