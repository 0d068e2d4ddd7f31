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
