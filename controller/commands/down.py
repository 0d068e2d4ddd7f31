"""``fleet down [--config F] [--wait] [--timeout S] [--json]``: stop a lab ``fleet up
--detach`` started.

Without ``--wait`` the lab stops now: the e-stop first (every robot stopped), then the daemon
(its MCAP closed whole), the agents, the world and the hub. With ``--wait`` it first waits for
the job's end (the lab stops itself then). Either way it prints the lab's verdict line and exits
with the job's code: 0 when the job did what the config asks, 1 when it failed or was stopped
(or no lab of the fleet ever ran here).
"""

from __future__ import annotations

from controller.commands import add_config_argument

EXAMPLES = """examples:
  fleet down --config lab.toml            # stop the lab now (e-stop first)
  fleet down --config lab.toml --wait     # wait for the job's end, then its verdict
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument(
        "--wait", action="store_true", help="wait for the job's end before stopping the lab"
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=0.0,
        help="--wait: stop the lab anyway after S seconds (0: wait as long as the job runs)",
    )
    parser.add_argument("--json", action="store_true", help="print the lab's outcome as JSON")


def run(args) -> int:
    from controller.runtime.lab_launch import down

    return down(args)
