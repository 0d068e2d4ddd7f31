"""``fleet status|estop|resume [--config F ...] [--json]``: talk to the fleet over the bus.

``status`` queries the daemon's status queryable (exit 1 when no daemon answers) and names
the controller that answers (``controller``; ``controllers``: every one that answered). ``estop``
publishes a latched emergency stop straight to the agents (through the hub: ``fleet hub``, or
the one a daemon starts when none runs): every agent stops its robot and refuses commands until
an operator's ``resume``. Both then ask every holder of the latch (``estop/state/<role>/<id>``)
until each known agent (the config's robots and every robot liveliness token) answers with the
new state; exit 0 when all did, 1 otherwise, naming those that did not; 3 when every agent did
but a hub or daemon cannot keep the latch in its state folder (``durable: false``, naming them in
``not_durable``), or a resume was refused (nothing put) because one cannot. The daemon's answer
is reported, not needed. ``holders`` lists every holder's answer: state, epoch, who set it.

A site: ``--config`` given once per fleet (``fleet estop --config cell_a.toml --config
cell_b.toml``) acts on every fleet at once, each through its own config's endpoints and
identity, in parallel: the site-wide e-stop. The exit status is the worst of the fleets'; the
text has a line per fleet after the site's verdict; ``--json`` has ``fleets`` (each fleet's own
object, with ``fleet``) beside the site's ``ok`` (and for estop/resume ``confirmed``,
``engaged`` and ``agents_missing`` as ``<fleet>/<robot>``). One ``--config`` prints as before.
"""

from __future__ import annotations

import sys

from controller.commands import DEFAULT_CONFIG, _DefaultConfig, distinct_fleets

EXAMPLES = {
    "status": """examples:
  fleet status                          the running daemon's phase, e-stop and robots
  fleet status --config fleet.toml --json
  fleet status --config cell_a.toml --config cell_b.toml     every fleet of a site
""",
    "estop": """examples:
  fleet estop --reason "person in the room"   stop every robot; wait for each to confirm
  fleet estop --config fleet.toml --json --timeout 5
  fleet estop --config cell_a.toml --config cell_b.toml      the site: every fleet at once
""",
    "resume": """examples:
  fleet resume                                release the e-stop once the room is clear
  fleet resume --config lab/secure.toml --user operator --password-file lab/secrets/operator.pw
""",
}


def add_arguments(parser, word: str) -> None:
    parser.add_argument(
        "--config",
        action="append",
        help="fleet config (default: fleet.toml); once per fleet for a site's fleets at once",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the daemon")
    parser.add_argument(
        "--connect", action="append", help="zenoh endpoint (default: the config's listen)"
    )
    parser.add_argument(
        "--user", help="zenoh user to authenticate as (an operator; default: the config's)"
    )
    parser.add_argument("--password-file", help="file holding --user's password")
    if word == "estop":
        parser.add_argument("--reason", default="", help="why (logged)")


def run(args) -> int:
    from controller.cli import emit_json
    from controller.config import load_config
    from controller.runtime.remote import act

    paths = args.config or [_DefaultConfig(DEFAULT_CONFIG)]
    cfgs = [load_config(p) for p in paths]  # every config read (exit 2 on any) before acting
    distinct_fleets(cfgs)
    a = act(cfgs, args._words[-1], args)
    if args.json:
        emit_json(a.obj)
    else:
        for line in a.out:
            print(line)
    for line in a.err:
        print(line, file=sys.stderr)
    return a.code
