"""One module per ``fleet`` subcommand: ``add_arguments(parser, word)`` and ``run(args) -> int``."""

DEFAULT_CONFIG = "fleet.toml"


def add_config_argument(parser) -> None:
    parser.add_argument(
        "--config", default=DEFAULT_CONFIG, help="fleet config (default: fleet.toml)"
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


def serve_until_signalled(args, serve) -> int:
    """Run a long-lived service (``fleet hub``, ``fleet world``): ``serve(cfg, stop, duration)``
    until SIGINT/SIGTERM sets ``stop`` or ``--duration`` s pass. A BusError maps to exit 1
    (cli.exit_code)."""
    import signal
    import threading

    from controller.config import load_config

    cfg = load_config(args.config)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return serve(cfg, stop, args.duration)
