"""``fleet check [--config F] [--json]``: validate a config; exit 2 naming the key path.

Everything ``fleet run`` would fail on before it starts: an unreadable or binary file, bad TOML,
unknown keys and values out of range, malformed zenoh endpoints, polygons, robots starting
outside the room, on an obstacle or on each other, identities shared between robots, the
controller and operators, and a ``log.dir`` that cannot be written (a temporary file, removed).
Beyond the loader it reads the certificates named in the config that exist here: two identities
with the same common name are refused."""

from __future__ import annotations

import sys

from controller.commands import add_config_argument, config_path
from controller.config import (
    ConfigError,
    InputError,
    certificate_problem,
    load_config,
    log_dir_problem,
)


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    from controller.cli import emit_json

    try:
        path = config_path(args)
    except InputError as exc:  # no --config and no fleet.toml here
        if args.json:
            emit_json({"ok": False, "file": str(args.config), "path": "", "error": str(exc)})
        print(f"fleet check: {exc}", file=sys.stderr)
        return 2
    try:
        cfg = load_config(path)
        problem = log_dir_problem(cfg.log.dir)  # what `fleet run` would fail on at its start
        if problem:
            raise ConfigError(cfg.source, "log.dir", problem)
        shared = certificate_problem(cfg)  # the certificates readable here, by common name
        if shared:
            raise ConfigError(cfg.source, *shared)
    except ConfigError as exc:
        if args.json:
            emit_json({"ok": False, "file": exc.source, "path": exc.path, "error": exc.message})
        print(f"fleet check: {exc}", file=sys.stderr)
        return 2
    summary = {
        "ok": True,
        "file": cfg.source,
        "fleet": cfg.fleet.name,
        "robots": list(cfg.robot_ids),
        "obstacles": len(cfg.obstacles),
        "notes": list(cfg.notes),
    }
    if args.json:
        emit_json(summary)
    else:
        print(f"{cfg.source}: ok ({len(cfg.robots)} robots, {len(cfg.obstacles)} obstacles)")
        print("".join(f"note: {n}\n" for n in cfg.notes), end="")
    return 0
