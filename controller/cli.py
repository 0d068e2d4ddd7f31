"""The ``fleet`` command line: ``main(argv) -> int``.

Each subcommand lives in ``controller/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``; their heavy imports happen only when their command runs, so ``fleet check``
never loads pybullet or zenoh. A command's ``--help`` teaches it: its description is the
module's ``DESCRIPTION`` or docstring (the synopsis left out: argparse prints the usage), its
epilog the module's ``EXAMPLES`` (a string, or a dict by command word for a module serving
several). Exit status: 0 done, 1 the job failed, 2 bad input or config. ``--json`` prints one
JSON object on stdout and nothing else there; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import re
import sys
from collections.abc import Sequence
from typing import Any

from controller.config import ConfigError, InputError

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2

# (command words, module, help)
COMMANDS: tuple[tuple[tuple[str, ...], str, str], ...] = (
    (("run",), "run", "the pybullet dry run of the whole job"),
    (("daemon",), "daemon", "the controller on the lab network"),
    (("driver",), "driver", "one robot's agent: its driver bound to the bus"),
    (("hub",), "hub", "the fleet's zenoh hub, keeper of the latched e-stop"),
    (("router",), "router", "a site's zenoh router: several fleets on one zenoh network"),
    (("world",), "world", "the shared stand-in world as its own process (lab rehearsal)"),
    (("up",), "up", "the whole lab from one config: hub, world, agents, daemon, a console"),
    (("down",), "down", "stop a lab that fleet up --detach started (--wait: after the job)"),
    (("status",), "remote", "query a running daemon's status"),
    (("estop",), "remote", "engage the latched emergency stop"),
    (("resume",), "remote", "release the emergency stop"),
    (("plan", "capture"), "plan_capture", "plan the capture points (GA), offline"),
    (("plan", "route"), "plan_route", "plan the object's route (A*), offline"),
    (("replay",), "replay", "metrics, plots and playback of a run's MCAP log"),
    (("record",), "record", "record a running fleet's bus to MCAP"),
    (("log", "recover"), "log_recover", "write a valid indexed copy of a log cut by a crash"),
    (("log", "layout"), "log_layout", "the shipped Foxglove layout: its path, or a copy"),
    (("sweep",), "sweep", "dry runs of several configs: a line each, a table at the end"),
    (("check",), "check", "validate a config"),
    (("schema",), "schema", "the JSON Schema of fleet.toml, for TOML editors"),
    (("init",), "init", "write an example config (fleet.toml, lab.toml) to start from"),
)
GROUPS = {
    "plan": ("run a planner alone, offline", "what"),
    "log": ("work on log files (MCAP)", "action"),
}
# a group's --help: (description, examples)
GROUP_HELP = {
    "plan": (
        "Run one of the controller's planners alone, offline, on a config's scenario (or a\n"
        "shipped route map): no robots, no bus. Each prints its plan (--json: one object) and\n"
        "exits 0 with a plan, 1 without one, 2 on bad input.",
        """examples:
  fleet plan capture                         the capture points for ./fleet.toml's object
  fleet plan route --map yamashita --goal 4  the object's route on a shipped map
""",
    ),
    "log": (
        "Work on the MCAP logs that fleet run, fleet daemon and fleet record write (read them\n"
        "with fleet replay).",
        """examples:
  fleet log recover runs/demo.mcap runs/demo-fixed.mcap   a valid copy of a crash-cut log
  fleet log layout --out layout.json                      the Foxglove layout, to import
""",
    ),
}
START_HERE = """start here:
  fleet run                       the dry run of ./fleet.toml in pybullet (what make run does)
  fleet check --config F          validate a config: every error, naming its key
  fleet COMMAND --help            what a command does, with examples
"""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse exits 2 already; keep its message
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fleet",
        description="Robot fleet controller: capture and transport.",
        epilog=START_HERE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging on stderr")
    parser.add_argument(
        "--version", action="version", version=f"fleet {version()}", help="print the version"
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    groups: dict[str, Any] = {}
    for words, module, help_ in COMMANDS:
        mod = importlib.import_module(f"controller.commands.{module}")
        texts = {
            "help": help_,
            "description": description(mod),
            "epilog": examples(mod, words[-1]),
            "formatter_class": argparse.RawDescriptionHelpFormatter,
        }
        if len(words) == 1:
            p = sub.add_parser(words[0], **texts)
        else:
            if words[0] not in groups:
                ghelp, dest = GROUPS[words[0]]
                gdesc, gexamples = GROUP_HELP.get(words[0], (None, None))
                g = sub.add_parser(
                    words[0],
                    help=ghelp,
                    description=gdesc,
                    epilog=gexamples,
                    formatter_class=argparse.RawDescriptionHelpFormatter,
                )
                groups[words[0]] = g.add_subparsers(dest=dest, required=True, parser_class=_Parser)
            p = groups[words[0]].add_parser(words[1], **texts)
        p.set_defaults(_module=module, _words=words)
        mod.add_arguments(p, words[-1])
    return parser


# a docstring's synopsis: ``fleet run [--config F] ...`` (argparse prints the usage itself)
_SYNOPSIS = re.compile(r"^``fleet [^`]*``[:.]?\s*")


def description(mod: Any) -> str | None:
    """A command's --help text: its module's ``DESCRIPTION``, else its docstring without the
    synopsis and without the reST double backquotes."""
    text = getattr(mod, "DESCRIPTION", None)
    if text is not None:
        return text.strip()
    paragraphs = []
    for para in (mod.__doc__ or "").strip().split("\n\n"):
        para, synopsis = _SYNOPSIS.subn("", para.strip())
        if synopsis:  # what followed it: a one-line summary, wrapped with the synopsis
            para = " ".join(para.split())
        if para:
            paragraphs.append((para[:1].upper() + para[1:]).replace("``", ""))
    return "\n\n".join(paragraphs) or None


def examples(mod: Any, word: str) -> str | None:
    """A command's examples (its module's ``EXAMPLES``: a string, or a dict by command word)."""
    text = getattr(mod, "EXAMPLES", None)
    if isinstance(text, dict):
        text = text.get(word)
    return text


def version() -> str:
    """The installed distribution's version, else (a source tree run without installing) the
    one in pyproject.toml."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("fleet-controller")
    except PackageNotFoundError:
        import tomllib
        from pathlib import Path

        pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
        try:
            return str(tomllib.loads(pyproject.read_text())["project"]["version"])
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "unknown"


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout (the --json contract)."""
    sys.stdout.write(json.dumps(obj, allow_nan=False, default=_json_default) + "\n")
    sys.stdout.flush()


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(list(argv) if argv is not None else None)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        stream=sys.stderr,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    mod = importlib.import_module(f"controller.commands.{args._module}")
    try:
        return int(mod.run(args))
    except KeyboardInterrupt:
        print("fleet: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        code = exit_code(exc)
        if code is None:
            raise
        what = " ".join(args._words)
        print(f"fleet {what}: {exc}", file=sys.stderr)
        if getattr(args, "json", False):
            emit_json({"ok": False, "status": "failed", "error": str(exc), "exit": code})
        return code


def exit_code(exc: BaseException) -> int | None:
    """The exit status of an expected error, in one place: bad config or input 2; a job that
    cannot start or a bus nobody answers on 1; None for a bug (the traceback is shown)."""
    if isinstance(exc, ConfigError | InputError):
        return EXIT_BAD_INPUT
    from controller.io.bus import BusError
    from controller.mission.job import MissionError

    if isinstance(exc, MissionError | BusError):
        return EXIT_FAILED
    return None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
