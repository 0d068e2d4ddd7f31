"""One module per ``fleet`` subcommand: ``add_arguments(parser, word)`` and ``run(args) -> int``."""

DEFAULT_CONFIG = "fleet.toml"
#: what a command that needs a config says when none was given and none is in this folder
NO_CONFIG_HERE = "no fleet.toml here: write one with fleet init (or pass --config F)"


class _DefaultConfig(str):
    """``--config``'s default, told apart from a ``--config fleet.toml`` given by the user."""


def add_config_argument(parser) -> None:
    parser.add_argument(
        "--config",
        default=_DefaultConfig(DEFAULT_CONFIG),
        help="fleet config (default: fleet.toml)",
    )


def config_path(args) -> str:
    """``args.config``; an InputError (exit 2) saying how to get one when no ``--config`` was
    given and there is no fleet.toml in the current folder (never a packaged example instead)."""
    from pathlib import Path

    from controller.config import InputError

    if isinstance(args.config, _DefaultConfig) and not Path(args.config).exists():
        raise InputError(NO_CONFIG_HERE)
    return args.config


def add_emulation_arguments(parser) -> None:
    """``--mavlink [IDS]`` and ``--ros2 [IDS]``: robots emulated as bodies of the stand-in world
    (``fleet world``, and ``fleet up`` when rehearsing)."""
    for flag, what in (
        ("--mavlink", "MAVLink robots as emulated vehicles of the stand-in world, answering "
         "their url on loopback"),
        ("--ros2", "ROS 2 robots as bodies of the stand-in world, on their rmw_zenoh keys at "
         "their ros2.connect endpoints on loopback"),
    ):  # fmt: skip
        parser.add_argument(
            flag,
            nargs="?",
            const="all",
            default=None,
            metavar="IDS",
            help=f"{what} (all of them, or the ids given, comma-separated)",
        )


def require_log_target(cfg, out, explicit: bool) -> None:
    """Fail early (exit 2) when the run's log cannot be written: ``log.dir`` (ConfigError naming
    the key) or the ``--out`` given (InputError)."""
    from pathlib import Path

    from controller.config import ConfigError, InputError, log_dir_problem

    problem = log_dir_problem(Path(out).parent)
    if problem is None:
        return
    if explicit:
        raise InputError(f"--out {out}: {problem}")
    raise ConfigError(cfg.source, "log.dir", problem)


def stop_on_signals():
    """A ``threading.Event`` set on SIGINT or SIGTERM. The handler only writes a byte to a pipe;
    a relay thread sets the event. ``Event.set()`` in the handler itself deadlocks when the
    signal lands while the main thread is inside ``stop.wait()`` holding the event's lock (the
    handler then waits for that lock forever): a ``fleet hub`` its daemon had started never
    stopped on the SIGTERM of its daemon's death."""
    import os
    import signal
    import threading

    stop = threading.Event()
    r, w = os.pipe()
    os.set_blocking(w, False)

    def relay() -> None:
        os.read(r, 1)
        stop.set()

    def handler(*_) -> None:
        try:
            os.write(w, b"\0")
        except OSError:  # the pipe full: a byte is already on its way
            pass

    threading.Thread(target=relay, name="signal-relay", daemon=True).start()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)
    return stop


def serve_until_signalled(args, serve) -> int:
    """Run a long-lived service (``fleet hub``, ``fleet world``): ``serve(cfg, stop, duration)``
    until SIGINT/SIGTERM sets ``stop`` or ``--duration`` s pass. A BusError maps to exit 1
    (cli.exit_code)."""
    from controller.config import load_config

    cfg = load_config(args.config)
    return serve(cfg, stop_on_signals(), args.duration)


def report_config_errors(args, errors) -> int:
    """Every error a line on stderr, then their count; ``--json``: the first one as before
    (``path``, ``error``) and all of them (``errors``). Exit 2."""
    import sys

    from controller.cli import emit_json

    first = errors[0]
    if args.json:
        emit_json(
            {
                "ok": False,
                "file": first.source,
                "path": first.path,
                "error": first.message,
                "errors": [{"key": e.path, "message": e.message} for e in errors],
            }
        )
    for e in errors:
        print(f"fleet check: {e}", file=sys.stderr)
    n = len(errors)
    print(f"fleet check: {n} error{'s' if n > 1 else ''} in {first.source}", file=sys.stderr)
    return 2


def distinct_fleets(cfgs) -> None:
    """InputError (exit 2) when two of the configs given are the same fleet (``fleet.name``)."""
    from controller.config import InputError

    names = [c.fleet.name for c in cfgs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"--config: fleet {twice[0]!r} given twice (fleet.name)")
