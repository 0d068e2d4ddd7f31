"""``fleet hub [--config F] [--duration S]``: the fleet's meeting point and e-stop keeper.

A zenoh router on the config's ``zenoh.listen`` endpoints that agents, the daemon and the tools
connect to, holding the latched e-stop (``controller.runtime.hub``). Start it before the daemon
(which then joins it instead of listening). Stops on SIGINT/SIGTERM; exit 1 when the endpoints
are taken.
"""

from __future__ import annotations

from controller.commands import add_config_argument, serve_until_signalled

EXAMPLES = """examples:
  fleet hub                               the hub of ./fleet.toml on its zenoh.listen endpoints
  fleet hub --config lab/secure.toml      the lab's secure profile (TLS, users, ACL)
  fleet hub --duration 600                stop after ten minutes
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")


def run(args) -> int:
    from controller.runtime.hub import run_hub

    return serve_until_signalled(args, run_hub)
