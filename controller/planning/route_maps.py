"""Route maps: route-planning scenarios shipped in ``controller/planning/maps/*.toml``."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller import geometry
from controller.planning.route import FloatArray


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

    def goal(self, which: str | int) -> FloatArray:
        """A goal by name, or by number counted from 1."""
        if isinstance(which, int) or str(which).isdigit():
            i = int(which) - 1
            if not 0 <= i < len(self.goals):
                raise KeyError(f"goal {which}: this map has goals 1..{len(self.goals)}")
            return self.goals[i][1]
        for n, g in self.goals:
            if n == which:
                return g
        raise KeyError(f"goal {which!r}: known goals {[n for n, _ in self.goals]}")


def parse_route_map(data: dict[str, Any], source: str = "") -> RouteMap:
    """Validate a parsed route-map TOML document (see ``controller/maps/*.toml``).

    Raises ValueError naming the source and the key.
    """

    def need(d: dict[str, Any], key: str, where: str) -> Any:
        if key not in d:
            raise ValueError(f"{source}: {where}{key}: missing")
        return d[key]

    try:
        m = need(data, "map", "")
        world = need(data, "world", "")
        obj = need(data, "object", "")
        bounds = np.asarray(need(world, "bounds", "world."), dtype=float).reshape(2, 2)
        obstacles = tuple(
            np.asarray(need(o, "polygon", f"obstacles[{i}]."), dtype=float)
            for i, o in enumerate(data.get("obstacles", []))
        )
        footprint = geometry.ensure_ccw(np.asarray(need(obj, "polygon", "object."), dtype=float))
        start = np.asarray(need(obj, "start", "object."), dtype=float).reshape(3)
        goals = tuple(
            (str(need(g, "name", f"goals[{i}].")), np.asarray(g["pose"], dtype=float).reshape(3))
            for i, g in enumerate(need(data, "goals", ""))
        )
        radius = float(need(m, "robot_radius", "map."))
    except (TypeError, KeyError) as exc:
        raise ValueError(f"{source}: malformed route map: {exc}") from exc
    return RouteMap(
        name=str(m.get("name", source)),
        bounds=bounds,
        obstacles=obstacles,
        footprint=footprint,
        robot_radius=radius,
        start=start,
        goals=goals,
    )


def maps_dir() -> Path:
    """Where the shipped route maps live."""
    return Path(__file__).resolve().parent / "maps"


def load_route_map(name_or_path: str):
    """Read a route map by shipped name or path (raises ValueError naming the file)."""
    p = Path(name_or_path)
    if not p.suffix:
        p = maps_dir() / f"{name_or_path}.toml"
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        known = sorted(q.stem for q in maps_dir().glob("*.toml"))
        raise ValueError(
            f"{p}: cannot read ({exc.strerror or exc}); shipped maps: {known}"
        ) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{p}: not valid TOML: {exc}") from exc
    return parse_route_map(data, str(p))
