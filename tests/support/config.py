"""Test configs: free loopback ports and configs derived from the shipped fleet.toml."""

from __future__ import annotations

import copy
import socket
import tomllib
from pathlib import Path
from typing import Any

from controller.config import FleetConfig, parse_config

ROOT = Path(__file__).resolve().parents[2]
FLEET_TOML = ROOT / "fleet.toml"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def base_config_dict(transport: bool = False) -> dict[str, Any]:
    """The shipped fleet.toml as data; without ``transport`` the object has no goal (a capture
    job: the run ends at the arrest, as most tests want)."""
    with open(FLEET_TOML, "rb") as f:
        data = tomllib.load(f)
    if not transport:
        data["object"].pop("goal", None)
    return data


def deep_update(d: dict[str, Any], patch: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(d)
    for k, v in patch.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_update(out[k], v)
        else:
            out[k] = v
    return out


def make_config(
    patch: dict[str, Any] | None = None, port: int | None = None, transport: bool = False
) -> FleetConfig:
    """The shipped config with a patch applied and zenoh on a free loopback port (a capture job
    unless ``transport``: see base_config_dict)."""
    data = deep_update(base_config_dict(transport), patch or {})
    p = port or free_port()
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{p}"], "connect": []}
    return parse_config(data, "test")


def write_toml(path: Path, data: dict[str, Any]) -> Path:
    """Write a config dict as TOML (enough of TOML for our configs)."""
    lines: list[str] = []

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        return repr(v)

    for k, v in data.items():
        if not isinstance(v, dict | list) or (
            isinstance(v, list) and v and not isinstance(v[0], dict)
        ):
            lines.append(f"{k} = {val(v)}")
    for k, v in data.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {val(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines.append(f"[[{k}]]")
                lines += [f"{kk} = {val(vv)}" for kk, vv in item.items()]
    path.write_text("\n".join(lines) + "\n")
    return path
