"""One module per ``fleet`` subcommand: ``add_arguments(parser, word)`` and ``run(args) -> int``."""

DEFAULT_CONFIG = "fleet.toml"


def add_config_argument(parser) -> None:
    parser.add_argument(
        "--config", default=DEFAULT_CONFIG, help="fleet config (default: fleet.toml)"
    )
