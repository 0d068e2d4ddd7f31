"""Foxglove well-known message parts as plain JSON-ready dicts (pure: no I/O, no clock).

Every field the published Foxglove JSON schemas mark required is filled (empty arrays too):
Foxglove reads JSON messages only when they match the schema named on their channel. Units are
metres and radians; frames are ENU (x east, y north, z up); times are seconds, turned into
``{sec, nsec}`` here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from controller import geometry

Color = tuple[float, float, float, float]

LINE_STRIP, LINE_LOOP, LINE_LIST = 0, 1, 2
LOG_DEBUG, LOG_INFO, LOG_WARNING, LOG_ERROR = 1, 2, 3, 4
IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def stamp(t: float) -> dict[str, int]:
    """A Foxglove time ``{sec, nsec}`` of ``t`` seconds (clamped at 0: the schema's minimum)."""
    ns = max(0, int(round(t * 1e9)))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def color(c: Color) -> dict[str, float]:
    return {"r": float(c[0]), "g": float(c[1]), "b": float(c[2]), "a": float(c[3])}


def vec3(x: float, y: float, z: float = 0.0) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def yaw_quat(yaw: float) -> dict[str, float]:
    """The quaternion of a rotation by ``yaw`` rad about z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2.0), "w": math.cos(yaw / 2.0)}


def pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> dict[str, Any]:
    return {"position": vec3(x, y, z), "orientation": yaw_quat(yaw)}


def entity(
    eid: str,
    t: float,
    frame: str,
    *,
    frame_locked: bool = False,
    metadata: dict[str, str] | None = None,
    **prims: list[dict[str, Any]],
) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` that lives until replaced (lifetime 0), with the primitive lists
    given (``arrows``, ``cubes``, ``spheres``, ``cylinders``, ``lines``, ``triangles``,
    ``texts``) and every other list empty."""
    out: dict[str, Any] = {
        "timestamp": stamp(t),
        "frame_id": frame,
        "id": eid,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": frame_locked,
        "metadata": [{"key": k, "value": str(v)} for k, v in (metadata or {}).items()],
    }
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts"):
        out[kind] = list(prims.pop(kind, []))
    out["models"] = []
    if prims:
        raise TypeError(f"unknown primitive lists {sorted(prims)}")
    return out


def scene_update(entities: Sequence[dict[str, Any]]) -> dict[str, Any]:
    return {"deletions": [], "entities": list(entities)}


def cylinder(x: float, y: float, z: float, diameter: float, height: float, c: Color) -> dict:
    return {
        "pose": pose(x, y, z),
        "size": vec3(diameter, diameter, height),
        "bottom_scale": 1.0,
        "top_scale": 1.0,
        "color": color(c),
    }


def sphere(x: float, y: float, z: float, diameter: float, c: Color) -> dict:
    return {"pose": pose(x, y, z), "size": vec3(diameter, diameter, diameter), "color": color(c)}


def cube(x: float, y: float, z: float, size: tuple[float, float, float], yaw: float, c: Color):
    return {"pose": pose(x, y, z, yaw), "size": vec3(*size), "color": color(c)}


def arrow(
    x: float, y: float, z: float, yaw: float, length: float, c: Color, width: float = 0.03
) -> dict:
    """An arrow from (x, y, z) along ``yaw`` of total ``length`` m (head a quarter of it)."""
    head = min(0.25 * length, 3 * width)
    return {
        "pose": pose(x, y, z, yaw),
        "shaft_length": max(length - head, 0.0),
        "shaft_diameter": width,
        "head_length": head,
        "head_diameter": 2.0 * width,
        "color": color(c),
    }


def line(kind: int, points: np.ndarray, c: Color, z: float = 0.0, thickness: float = 0.02):
    """A line primitive through (N, 2) points at height ``z`` (thickness in m)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return {
        "type": kind,
        "pose": pose(),
        "thickness": thickness,
        "scale_invariant": False,
        "points": [vec3(p[0], p[1], z) for p in pts],
        "color": color(c),
        "colors": [],
        "indices": [],
    }


def text(x: float, y: float, z: float, words: str, c: Color, size: float = 14.0) -> dict:
    """A label that faces the camera, ``size`` pixels high."""
    return {
        "pose": pose(x, y, z),
        "billboard": True,
        "font_size": size,
        "scale_invariant": True,
        "color": color(c),
        "text": words,
    }


def triangulate(poly: np.ndarray) -> list[tuple[int, int, int]]:
    """Ear clipping of a simple polygon (any orientation): index triples, CCW."""
    p = geometry.ensure_ccw(np.asarray(poly, dtype=float))
    idx = list(range(len(p)))
    tris: list[tuple[int, int, int]] = []

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    guard = 0
    while len(idx) > 3 and guard < 10 * len(p) ** 2:
        guard += 1
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = p[i0], p[i1], p[i2]
            if cross(a, b, c) <= 1e-12:
                continue  # reflex or degenerate: not an ear
            others = [j for j in idx if j not in (i0, i1, i2)]
            if any(
                cross(a, b, p[j]) >= 0 and cross(b, c, p[j]) >= 0 and cross(c, a, p[j]) >= 0
                for j in others
            ):
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
        else:
            break  # numerically stuck: fan the rest
    tris += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    return tris


def prism(poly: np.ndarray, height: float, c: Color, z0: float = 0.0) -> dict:
    """A ``TriangleListPrimitive``: the polygon extruded from ``z0`` to ``z0 + height`` (top face
    and walls; the bottom lies on the floor, unseen)."""
    p = geometry.ensure_ccw(np.asarray(poly, dtype=float))
    top = z0 + height
    pts: list[dict[str, float]] = []
    for i, j, k in triangulate(p):
        pts += [vec3(*p[i], top), vec3(*p[j], top), vec3(*p[k], top)]
    for a, b in zip(p, np.roll(p, -1, axis=0), strict=True):
        pts += [vec3(*a, z0), vec3(*b, z0), vec3(*b, top)]
        pts += [vec3(*a, z0), vec3(*b, top), vec3(*a, top)]
    return {"pose": pose(), "points": pts, "color": color(c), "colors": [], "indices": []}


def transform(t: float, parent: str, child: str, x: float, y: float, yaw: float) -> dict:
    """A ``foxglove.FrameTransform`` placing ``child`` at (x, y, yaw) in ``parent``."""
    return {
        "timestamp": stamp(t),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": vec3(x, y, 0.0),
        "rotation": yaw_quat(yaw),
    }


def log_entry(t: float, level: int, message: str, name: str = "controller") -> dict[str, Any]:
    """A ``foxglove.Log`` line."""
    return {
        "timestamp": stamp(t),
        "level": level,
        "message": message,
        "name": name,
        "file": "",
        "line": 0,
    }
