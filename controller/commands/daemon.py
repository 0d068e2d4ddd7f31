"""`fleet daemon`: not built yet (see the issues)."""

from __future__ import annotations

import sys

from controller.commands import add_config_argument


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    print("fleet: this command is not built yet", file=sys.stderr)
    return 1
