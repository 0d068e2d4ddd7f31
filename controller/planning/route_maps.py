"""Route maps (``controller/planning/maps/*.toml``) and the scenario of ``fleet plan route``.

A route map is validated like fleet.toml (the same walker: unknown keys with a did-you-mean,
types, ranges, polygons): every error is a :class:`controller.config.ConfigError` naming the file
and the key path, never a traceback.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import (
    ConfigError,
    Point,
    Polygon,
    Pose,
    RouteSection,
    check_route_grid,
    load_config,
    override,
    parse_table,
    validated_polygon,
)
from controller.planning.route import FloatArray


@dataclass(frozen=True, kw_only=True)
class _MapInfo:
    name: str = ""
    robot_radius: float = field(metadata={"min": 0, "max": 5})


@dataclass(frozen=True, kw_only=True)
class _MapWorld:
    bounds: tuple[Point, Point]


@dataclass(frozen=True, kw_only=True)
class _MapObject:
    polygon: Polygon
    start: Pose


@dataclass(frozen=True, kw_only=True)
class _MapGoal:
    name: str
    pose: Pose


@dataclass(frozen=True, kw_only=True)
class _MapObstacle:
    polygon: Polygon


@dataclass(frozen=True, kw_only=True)
class _MapFile:
    map: _MapInfo
    world: _MapWorld
    object: _MapObject
    goals: tuple[_MapGoal, ...]
    obstacles: tuple[_MapObstacle, ...] = ()


@dataclass(frozen=True, eq=False)
class RouteMap:
    """A route-planning scenario: bounds (m), obstacles, object polygon, start and named goals."""

    name: str
    bounds: FloatArray
    obstacles: tuple[FloatArray, ...]
    footprint: FloatArray
    robot_radius: float
    start: FloatArray
    goals: tuple[tuple[str, FloatArray], ...]
    source: str = ""

    def goal(self, which: str | int) -> FloatArray:
        """A goal by name, or by number counted from 1 (ConfigError naming ``goals``)."""
        names = [n for n, _ in self.goals]
        if isinstance(which, int) or str(which).isdigit():
            i = int(which) - 1
            if 0 <= i < len(self.goals):
                return self.goals[i][1]
        else:
            for n, g in self.goals:
                if n == which:
                    return g
        raise ConfigError(
            self.source,
            "goals",
            f"no goal {which!r}: this map has goals 1..{len(self.goals)} ({', '.join(names)})",
        )


def parse_route_map(data: dict[str, Any], source: str = "") -> RouteMap:
    """Validate a parsed route-map TOML document (raises ConfigError naming source and key)."""
    doc = parse_table(_MapFile, data, "", source)
    (x0, y0), (x1, y1) = doc.world.bounds
    if not (x1 > x0 and y1 > y0):
        raise ConfigError(
            source, "world.bounds", "expected [[xmin, ymin], [xmax, ymax]] with max > min"
        )
    if not doc.goals:
        raise ConfigError(source, "goals", "expected at least one [[goals]] entry")
    seen: dict[str, int] = {}
    for i, g in enumerate(doc.goals):
        if g.name in seen:
            raise ConfigError(
                source,
                f"goals[{i}].name",
                f"duplicate goal {g.name!r} (also goals[{seen[g.name]}])",
            )
        seen[g.name] = i
    obstacles = tuple(
        np.asarray(validated_polygon(o.polygon, f"obstacles[{i}].polygon", source))
        for i, o in enumerate(doc.obstacles)
    )
    return RouteMap(
        name=doc.map.name or source,
        bounds=np.asarray(doc.world.bounds, dtype=float),
        obstacles=obstacles,
        footprint=np.asarray(validated_polygon(doc.object.polygon, "object.polygon", source)),
        robot_radius=float(doc.map.robot_radius),
        start=np.asarray(doc.object.start, dtype=float),
        goals=tuple((g.name, np.asarray(g.pose, dtype=float)) for g in doc.goals),
        source=source,
    )


def maps_dir() -> Path:
    """Where the shipped route maps live."""
    return Path(__file__).resolve().parent / "maps"


def load_route_map(name_or_path: str) -> RouteMap:
    """Read a route map by shipped name or path (ConfigError naming the file and key)."""
    p = Path(name_or_path)
    if not p.suffix:
        p = maps_dir() / f"{name_or_path}.toml"
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        known = sorted(q.stem for q in maps_dir().glob("*.toml"))
        raise ConfigError(
            str(p), "", f"cannot read ({exc.strerror or exc}); shipped maps: {known}"
        ) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(str(p), "", f"not valid TOML: {exc}") from exc
    return parse_route_map(data, str(p))


@dataclass(frozen=True, eq=False)
class RouteScenario:
    """What ``fleet plan route`` plans: the room, the object, its start and goal, the params."""

    bounds: FloatArray
    obstacles: list[FloatArray]
    footprint: FloatArray
    robot_radius: float
    start: FloatArray
    goal: FloatArray
    params: RouteSection
    source: str


def route_scenario(
    config: str | None, map_name: str | None, goal: str, overrides: dict[str, Any]
) -> RouteScenario:
    """The scenario of ``fleet plan route``: a route map's (``map_name``, toward ``goal``) or the
    fleet config's; ``[route]`` from the config (defaults for a map without a config), with
    ``overrides`` (command-line values, checked by the field rules and named ``--key``).
    Raises ConfigError naming the file (or the flag) and the key; checks the grid budget."""
    params = RouteSection()
    cfg = None
    if config is None and map_name is None:
        raise ConfigError("command line", "--config", "give a config or a --map")
    if config is not None:
        cfg = load_config(config)
        params = cfg.route
    params = override(params, overrides, "command line", "--")
    if map_name is not None:
        rmap = load_route_map(map_name)
        sc = RouteScenario(
            rmap.bounds,
            list(rmap.obstacles),
            rmap.footprint,
            rmap.robot_radius,
            rmap.start,
            rmap.goal(goal),
            params,
            rmap.source,
        )
    else:
        assert cfg is not None
        if cfg.object.goal is None:
            raise ConfigError(cfg.source, "object.goal", "no goal to plan a route to (give one)")
        sc = RouteScenario(
            cfg.bounds_array(),
            cfg.obstacle_polygons(),
            cfg.object_polygon(),
            cfg.max_robot_radius,
            np.asarray(cfg.object.start, dtype=float),
            np.asarray(cfg.object.goal, dtype=float),
            params,
            cfg.source,
        )
    check_route_grid(sc.bounds.tolist(), params, sc.source)
    return sc
