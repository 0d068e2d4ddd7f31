"""Every figure of the project (the only matplotlib importer): run plots, capture and route
plans. Figures are written as PNG files with the Agg backend (no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controller import geometry
from controller.replay import metrics
from controller.replay.log import RunLog, _track


def plot_run(run: RunLog, out_dir: str | Path) -> list[Path]:
    """PNG plots of a run: trajectories (with obstacles and object outlines), robot clearance
    and estimation error over time. Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = run.config
    ids = list(cfg.robot_ids) if cfg else sorted(set(run.measured) | set(run.truth))
    src = run.truth if run.truth else (run.estimated or run.measured)
    written: list[Path] = []

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
    written.append(out / "trajectories.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    if cfg is not None and len(ids) > 1:
        tracks = [_track(src.get(rid, [])) for rid in ids]
        tracks_h = [tr for tr in tracks if len(tr)]
        radii = np.array(
            [cfg.robot(r).radius for r, tr in zip(ids, tracks, strict=True) if len(tr)]
        )
        grid = metrics.common_grid(tracks_h)
        if len(grid) and len(tracks_h) > 1:
            xy = np.stack([tr.at(grid)[:, :2] for tr in tracks_h], axis=1)
            d = np.linalg.norm(xy[:, :, None] - xy[:, None, :], axis=-1)
            gap = d - radii[None, :, None] - radii[None, None, :]
            n = len(tracks_h)
            gap[:, np.arange(n), np.arange(n)] = np.inf
            fig, ax = plt.subplots(figsize=(7, 3))
            ax.plot(grid, gap.min(axis=(1, 2)))
            ax.axhline(0, color="r", lw=0.8)
            ax.set_xlabel("t (s)")
            ax.set_ylabel("min robot gap (m)")
            written.append(out / "clearance.png")
            fig.savefig(written[-1], dpi=110, bbox_inches="tight")
            plt.close(fig)

    if run.truth and run.estimated:
        fig, ax = plt.subplots(figsize=(7, 3))
        for rid in ids:
            est, truth = _track(run.estimated.get(rid, [])), _track(run.truth.get(rid, []))
            if len(est) and len(truth) > 1:
                err = np.linalg.norm(est.pose[:, :2] - truth.at(est.t)[:, :2], axis=1)
                ax.plot(est.t, err * 100, lw=0.8, label=rid)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("estimate error (cm)")
        ax.legend(fontsize=7)
        written.append(out / "estimation_error.png")
        fig.savefig(written[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)
    return written
