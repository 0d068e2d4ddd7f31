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
