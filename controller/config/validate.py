"""Loading and validating a whole fleet.toml: the walk (controller/config/load.py) against the
sections, then the cross-field rules (polygons, unique ids, robot starts, driver rules, zenoh
security), and the config as plain data again (:func:`config_to_dict`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from controller import geometry
from controller.config.driver_sections import DRIVER_SPECS, validate_ros2_graph
from controller.config.load import (
    FAILED,
    ConfigError,
    ConfigErrors,
    _build,
    _convert,
    _Reported,
    attempt,
    collecting,
    found,
    nesting_error,
    read_toml,
)
from controller.config.sections import (
    CAPTURE_NODE_BUDGET,
    MIN_TIMESTEP,
    ROBOT_ROUTE_MAX_CELLS,
    ROUTE_MAX_STATES,
    FleetConfig,
    ObjectSection,
    Obstacle,
    Point,
    Polygon,
    RobotConfig,
    RouteSection,
)
from controller.config.security import _check_zenoh, _validate_zenoh

# --------------------------------------------------------------------------- cross-field rules


MAX_POLYGON_VERTICES = 1000  # the checks below are quadratic in the vertices (20 000: 6.9 GB)


def _polygon_size(poly: Any, path: str, src: str) -> None:
    """Refuse a polygon too large to check (before anything allocates for it)."""
    if len(poly) > MAX_POLYGON_VERTICES:
        raise ConfigError(
            src, path, f"{len(poly)} vertices: at most {MAX_POLYGON_VERTICES} (simplify it)"
        )


def _polygon(poly: Polygon, path: str, src: str) -> Polygon:
    _polygon_size(poly, path, src)
    p = np.asarray(poly, dtype=float)
    if len(p) < 3:
        raise ConfigError(src, path, f"expected a polygon of at least 3 vertices, got {len(p)}")
    bad = geometry.self_intersection(p)
    if bad is not None:
        i, j = bad
        if i == j:
            raise ConfigError(src, path, f"polygon has a zero-length edge at vertex {i}")
        raise ConfigError(
            src, path, f"polygon is not simple: edge {i} crosses edge {j} (self-intersection)"
        )
    area = geometry.signed_area(p)
    if abs(area) < 1e-9:
        raise ConfigError(src, path, "polygon has zero area")
    q = geometry.ensure_ccw(p)
    return tuple((float(x), float(y)) for x, y in q)


def _place_robot(cfg: FleetConfig, i: int, obstacles: tuple[Obstacle, ...], src: str) -> None:
    """A robot starts inside the room and clear of every obstacle."""
    r = cfg.robots[i]
    path = f"robots[{i}]"
    (x0, y0), (x1, y1) = cfg.world.bounds
    x, y, _ = r.start
    if not (x0 + r.radius <= x <= x1 - r.radius and y0 + r.radius <= y <= y1 - r.radius):
        raise ConfigError(
            src, f"{path}.start", f"robot {r.id!r} at ({x}, {y}) is not inside world.bounds"
        )
    for j, o in enumerate(obstacles):
        if geometry.discs_hit_polygon([[x, y]], r.radius, o.polygon)[0]:
            raise ConfigError(
                src, f"{path}.start", f"robot {r.id!r} at ({x}, {y}) overlaps obstacles[{j}]"
            )


def _validate_robots(cfg: FleetConfig, obstacles: Any, src: str) -> None:
    """Unique ids and each robot's driver rules; with valid ``world.bounds`` and ``obstacles``
    (else FAILED) where each robot starts. Each robot's errors are its own (collected)."""
    if not cfg.robots:
        raise ConfigError(src, "robots", "expected at least one [[robots]] entry")
    seen: dict[str, int] = {}
    for i, r in enumerate(cfg.robots):
        if r.id in seen:
            found(
                ConfigError(
                    src,
                    f"robots[{i}].id",
                    f"duplicate robot id {r.id!r} (also robots[{seen[r.id]}])",
                )
            )
        seen.setdefault(r.id, i)
        if obstacles is not FAILED:
            attempt(_place_robot, cfg, i, obstacles, src)
        if r.spec.validate is not None:
            attempt(r.spec.validate, cfg, i, src)
    if obstacles is not FAILED:
        _check_start_discs(cfg.robots, src)


def _check_start_discs(robots: tuple[RobotConfig, ...], src: str) -> None:
    """No two robots' start discs overlap (touching is fine)."""
    xy = np.array([r.start[:2] for r in robots], dtype=float)
    radii = np.array([r.radius for r in robots], dtype=float)
    gaps = geometry.disc_gaps(xy, radii)
    for j in range(len(robots)):
        for i in range(j):
            if gaps[i, j] < -1e-9:
                a, b = robots[i], robots[j]
                d = float(np.hypot(*(xy[j] - xy[i])))
                found(
                    ConfigError(
                        src,
                        f"robots[{j}].start",
                        f"robot {b.id!r} at {list(b.start[:2])} overlaps robot {a.id!r} "
                        f"(robots[{i}]) at {list(a.start[:2])}: centres {d:.3g} m apart, radii "
                        f"sum {a.radius + b.radius:.3g} m",
                    )
                )


def log_dir_problem(directory: str | Path) -> str | None:
    """Why logs cannot be written in ``directory`` (created if missing), or None. Probes with a
    temporary file; creates nothing that stays."""
    d = Path(directory)
    probe = d
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        return f"{str(probe)!r} is not a directory (log files go in {str(d)!r})"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{str(probe)!r} is not writable (log files go in {str(d)!r})"
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as exc:
        return f"cannot write in {str(probe)!r}: {exc.strerror or exc}"
    return None


def edge_node_counts(polygon: Any, spacing: float) -> np.ndarray:
    """Capture candidate nodes per edge at ``spacing``: max(1, floor(length / spacing)), as
    floats (a tiny spacing gives huge counts, never an overflow)."""
    p = np.asarray(polygon, dtype=float)
    lengths = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    with np.errstate(over="ignore"):
        return np.maximum(1.0, np.floor(lengths / spacing + 1e-9))


def capture_budget_error(polygon: Any, spacing: float) -> str | None:
    """Why ``spacing`` gives the capture planner more nodes than its budget, or None."""
    n = float(edge_node_counts(polygon, spacing).sum())
    if n <= CAPTURE_NODE_BUDGET:
        return None
    p = np.asarray(polygon, dtype=float)
    per = float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum())
    least = per / (CAPTURE_NODE_BUDGET - len(p))
    return (
        f"{spacing:g} m gives {n:.4g} candidate nodes on the object's boundary (perimeter "
        f"{per:.4g} m); the capture planner's budget is {CAPTURE_NODE_BUDGET}: "
        f"use capture.spacing >= {least:.3g}"
    )


def merge_vertices(poly: Any, tol: float = 1e-9) -> tuple[np.ndarray, int, int]:
    """The polygon without repeated vertices (closer than ``tol`` m, a closing copy of the first
    one included) and without vertices in the middle of a straight edge (|sin| of the turn below
    ``tol``, the edges going on the same way): (vertices, duplicates removed, collinear removed).
    The shape is unchanged; what changes is what "one robot per edge" counts."""
    p = np.asarray(poly, dtype=float)
    dup = col = 0
    changed = True
    while changed and len(p) > 3:
        changed = False
        step = np.roll(p, -1, axis=0) - p  # edge i: p[i] -> p[i+1]
        length = np.linalg.norm(step, axis=1)
        if np.any(length <= tol):
            i = int(np.argmax(length <= tol))
            p = np.delete(p, i + 1 if i + 1 < len(p) else i, axis=0)  # keep the first vertex
            dup, changed = dup + 1, True
            continue
        prev = np.roll(step, 1, axis=0)  # edge arriving at vertex i
        cross = prev[:, 0] * step[:, 1] - prev[:, 1] * step[:, 0]
        straight = (np.abs(cross) <= tol * np.roll(length, 1) * length) & (
            (prev * step).sum(axis=1) > 0
        )
        if np.any(straight):
            p = np.delete(p, int(np.argmax(straight)), axis=0)
            col, changed = col + 1, True
    return p, dup, col


def _object(cfg: FleetConfig, src: str) -> tuple[ObjectSection, tuple[str, ...]]:
    """The object section with its polygon merged (duplicate and collinear vertices, noted),
    validated and within the capture planner's node budget."""
    _polygon_size(cfg.object.polygon, "object.polygon", src)
    merged, dup, col = merge_vertices(cfg.object.polygon)
    notes = cfg.notes
    if dup or col:
        notes += (
            f"object.polygon: merged {dup} duplicate and {col} collinear vertices "
            f"({len(cfg.object.polygon)} -> {len(merged)}; the capture's one robot per edge "
            "counts the merged edges)",
        )
    obj = dataclasses.replace(cfg.object, polygon=_polygon(merged, "object.polygon", src))
    budget = capture_budget_error(obj.polygon, cfg.capture.spacing)
    if budget:
        raise ConfigError(src, "capture.spacing", budget)
    return obj, notes


def _validate(cfg: FleetConfig, src: str) -> FleetConfig:
    """Cross-field rules, after every key was checked on its own. The first error is raised; or,
    while collecting (``parse_config(..., all_errors=True)``), every rule runs whose inputs are
    valid: where robots and the object stand is checked only within valid ``world.bounds`` and
    around valid obstacles."""
    bounds = attempt(_check_bounds, cfg.world.bounds, src)
    obstacles = attempt(_obstacles, cfg, src)
    if bounds is FAILED:
        obstacles = FAILED  # the placements below need both
    merged = attempt(_object, cfg, src)  # (the object, the notes with its merged vertices)
    attempt(_check_timestep, cfg, src)
    attempt(_check_zenoh, cfg.zenoh, src)
    attempt(_validate_robots, cfg, obstacles, src)
    attempt(validate_ros2_graph, cfg, src)
    if obstacles is not FAILED and merged is not FAILED:
        attempt(_check_object_poses, merged[0], obstacles, cfg.world.bounds, src)
    if bounds is not FAILED:
        attempt(check_route_grid, cfg.world.bounds, cfg.route, src)
    secured = attempt(_validate_zenoh, cfg, src)
    if FAILED in (secured, obstacles, merged):
        raise _Reported
    obj, notes = merged
    notes += _driver_notes(cfg)
    return dataclasses.replace(secured, obstacles=obstacles, object=obj, source=src, notes=notes)


def _check_bounds(bounds: tuple[Point, Point], src: str) -> None:
    (x0, y0), (x1, y1) = bounds
    if not (x1 > x0 and y1 > y0):
        raise ConfigError(
            src, "world.bounds", "expected [[xmin, ymin], [xmax, ymax]] with max > min"
        )


def _obstacles(cfg: FleetConfig, src: str) -> tuple[Obstacle, ...]:
    """The obstacles with their polygons validated, each on its own."""
    out = tuple(
        attempt(_obstacle, o, f"obstacles[{i}].polygon", src) for i, o in enumerate(cfg.obstacles)
    )
    if FAILED in out:
        raise _Reported
    return out


def _obstacle(o: Obstacle, path: str, src: str) -> Obstacle:
    return dataclasses.replace(o, polygon=_polygon(o.polygon, path, src))


def _driver_notes(cfg: FleetConfig) -> tuple[str, ...]:
    """What each robot's driver entry has to say about the config (DriverSpec.notes)."""
    out: tuple[str, ...] = ()
    for i, r in enumerate(cfg.robots):
        if r.spec.notes is not None:
            out += r.spec.notes(cfg, i)
    return out


def _check_timestep(cfg: FleetConfig, src: str) -> None:
    """One physics step is at most one control tick (else a command may never be applied)."""
    tick = 1.0 / cfg.fleet.rate_hz
    if cfg.sim.timestep > tick + 1e-12:
        raise ConfigError(
            src,
            "sim.timestep",
            f"{cfg.sim.timestep:g} s is longer than one control tick (1 / fleet.rate_hz = "
            f"{tick:g} s): expected {MIN_TIMESTEP:g} <= sim.timestep <= {tick:g}",
        )


def _polygons_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two simple polygons share a point (touching counts)."""
    ea, eb = np.roll(a, -1, axis=0), np.roll(b, -1, axis=0)
    if geometry.segments_intersect(a[:, None], ea[:, None], b[None], eb[None]).any():
        return True
    return bool(geometry.points_in_polygon(a[:1], b)[0] or geometry.points_in_polygon(b[:1], a)[0])


def _check_object_poses(
    obj: ObjectSection, obstacles: tuple[Obstacle, ...], bounds: tuple[Point, Point], src: str
) -> None:
    """object.start and object.goal place the object inside the bounds, clear of obstacles."""
    (x0, y0), (x1, y1) = bounds
    for key in ("start", "goal"):
        pose = getattr(obj, key)
        if pose is None:  # no goal: a capture job
            continue
        world_poly = geometry.transform(np.asarray(obj.polygon), pose)
        if (
            world_poly[:, 0].min() < x0
            or world_poly[:, 0].max() > x1
            or world_poly[:, 1].min() < y0
            or world_poly[:, 1].max() > y1
        ):
            raise ConfigError(src, f"object.{key}", "the object placed there leaves world.bounds")
        for j, o in enumerate(obstacles):
            if _polygons_overlap(world_poly, np.asarray(o.polygon, dtype=float)):
                raise ConfigError(
                    src,
                    f"object.{key}",
                    f"the object placed at {list(pose)} overlaps obstacles[{j}]",
                )


def _cells(extent: float, resolution: float) -> int:
    return int(math.ceil(extent / resolution - 1e-9))


def check_route_grid(bounds: Any, route: RouteSection, src: str = "") -> None:
    """The route grids over ``bounds`` fit their budgets (:data:`ROUTE_MAX_STATES` object states,
    :data:`ROBOT_ROUTE_MAX_CELLS` robot cells); raises ConfigError naming the key."""
    (x0, y0), (x1, y1) = bounds
    nx, ny = _cells(x1 - x0, route.resolution), _cells(y1 - y0, route.resolution)
    states = nx * ny * route.heading_bins
    if states > ROUTE_MAX_STATES:
        raise ConfigError(
            src,
            "route.resolution",
            f"{route.resolution} m with route.heading_bins = {route.heading_bins} gives "
            f"{nx} x {ny} x {route.heading_bins} = {states / 1e6:.1f} M route states over "
            f"world.bounds, above the budget of {ROUTE_MAX_STATES / 1e6:.0f} M (minutes and "
            "gigabytes per plan); use a coarser route.resolution or fewer route.heading_bins",
        )
    rx = _cells(x1 - x0, route.robot_resolution)
    ry = _cells(y1 - y0, route.robot_resolution)
    if rx * ry > ROBOT_ROUTE_MAX_CELLS:
        raise ConfigError(
            src,
            "route.robot_resolution",
            f"{route.robot_resolution} m gives {rx} x {ry} robot route cells over world.bounds, "
            f"above the budget of {ROBOT_ROUTE_MAX_CELLS} (the robots' routes are planned "
            "during the run); use a coarser route.robot_resolution",
        )


def validated_polygon(poly: Any, path: str, source: str = "") -> Polygon:
    """A simple polygon of >= 3 vertices and non-zero area, counter-clockwise (ConfigError if
    not, naming ``path``)."""
    if isinstance(poly, tuple | list):
        poly = [list(v) if isinstance(v, tuple) else v for v in poly]
    p = _convert(Polygon, poly, path, source)
    return _polygon(p, path, source)


def parse_config(data: dict[str, Any], source: str = "", all_errors: bool = False) -> FleetConfig:
    """Validate a parsed TOML document into a FleetConfig (raises ConfigError: the first error;
    with ``all_errors`` ConfigErrors, every error found in one pass: unknown keys, types and
    ranges of every section and robot, then, when they all passed, the cross-field rules
    whose inputs are valid)."""
    deep = nesting_error(data)
    if deep:
        raise ConfigError(source, *deep)
    if not all_errors:
        return _validate(_build(FleetConfig, data, "", source), source)
    with collecting() as errors:
        cfg = attempt(_build, FleetConfig, data, "", source)
        if cfg is not FAILED:  # the cross-field rules need every key's own check passed
            cfg = attempt(_validate, cfg, source)
    if errors:
        raise ConfigErrors(errors)
    return cfg


def load_config(path: str | Path, all_errors: bool = False) -> FleetConfig:
    """Read and validate a fleet.toml (raises ConfigError naming the file and key path; with
    ``all_errors`` ConfigErrors listing every error, see :func:`parse_config`). A file that
    cannot be read or is not TOML is one error."""
    return parse_config(read_toml(path), str(Path(path)), all_errors)


# never written to logs or --json: passwords (a password_file is named, not read)
_SECRETS = ("password", "zenoh_password")
REDACTED = "<redacted>"


def config_to_dict(cfg: FleetConfig) -> dict[str, Any]:
    """The config as plain data (for logs and --json); tuples become lists. The loader's notes
    and unset optional keys (``object.goal`` None: TOML has no null) are left out: the data
    must load again. Passwords are written as ``<redacted>`` (a log or --json output is no
    place for them): such a config loads again but authenticates only with the original."""

    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return {
                f.name: REDACTED
                if f.name in _SECRETS and getattr(v, f.name)
                else conv(getattr(v, f.name))
                for f in dataclasses.fields(v)
                if f.name != "notes"
                and not f.metadata.get("internal")
                and getattr(v, f.name) is not None
            }
        if isinstance(v, tuple | list):
            return [conv(x) for x in v]
        return v

    out = conv(cfg)
    for robot, r in zip(out["robots"], cfg.robots, strict=True):
        for name, spec in DRIVER_SPECS.items():  # the flat keys too: readers of older logs
            robot.update({k: getattr(getattr(r, name), k) for k in spec.flat_keys})
            if name != r.driver:  # only the robot's own driver's sub-table loads again
                robot.pop(name, None)
    return out
