"""``fleet check [--config F] [--json]``: validate a config; exit 2 naming the key path."""

from __future__ import annotations

import sys

from controller.commands import add_config_argument
from controller.config import ConfigError, load_config


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    from controller.cli import emit_json

    try:
        cfg = load_config(args.config)
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
