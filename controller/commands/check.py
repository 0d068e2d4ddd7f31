"""``fleet check [--config F] [--json]``: validate a config; exit 2 naming every error's key path.

Everything ``fleet run`` would fail on before it starts: an unreadable or binary file, bad TOML,
unknown keys and values out of range, malformed zenoh endpoints, polygons, robots starting
outside the room, on an obstacle or on each other, identities shared between robots, the
controller and operators, and a ``log.dir`` that cannot be written (a temporary file, removed).
Beyond the loader it reads the certificates named in the config that exist here: two identities
with the same common name are refused.

Every error is reported in one run, a line each (file, key path, what is wrong), then their
count; only a file that cannot be read or parsed stops at once, and the rules between keys (a
robot inside the room, ...) run once every key passed its own check. ``--json`` prints one
object: ``ok``, ``file``, and on errors ``path`` and ``error`` (the first one) and ``errors``
(``[{key, message}, ...]``, all of them); when ok ``fleet``, ``robots``, ``obstacles``,
``notes``."""

from __future__ import annotations

import sys

from controller.commands import add_config_argument, config_path, report_config_errors
from controller.config import (
    ConfigError,
    InputError,
    certificate_problem,
    load_config,
    log_dir_problem,
)

EXAMPLES = """examples:
  fleet check                          check ./fleet.toml
  fleet check --config lab.toml        check another config
  fleet check --config lab.toml --json one JSON object: ok, errors [{key, message}, ...]
"""


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
        cfg = load_config(path, all_errors=True)
    except ConfigError as exc:
        return report_config_errors(args, getattr(exc, "errors", [exc]))
    errors = []
    problem = log_dir_problem(cfg.log.dir)  # what `fleet run` would fail on at its start
    if problem:
        errors.append(ConfigError(cfg.source, "log.dir", problem))
    from controller.runtime.estop import state_folder

    problem = log_dir_problem(state_folder(cfg))  # where the hub and daemon keep the e-stop
    if problem:
        where = (
            "fleet.state_dir" if cfg.fleet.state_dir or not cfg.log.state_dir else "log.state_dir"
        )
        errors.append(
            ConfigError(cfg.source, where, problem.replace("log files", "the e-stop latch"))
        )
    shared = certificate_problem(cfg)  # the certificates readable here, by common name
    if shared:
        errors.append(ConfigError(cfg.source, *shared))
    if errors:
        return report_config_errors(args, errors)
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
