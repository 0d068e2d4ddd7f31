"""``fleet status|estop|resume [--config F] [--json]``: talk to the fleet over the bus.

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
"""

from __future__ import annotations

import getpass
import socket
import sys

from controller.commands import add_config_argument

EXAMPLES = {
    "status": """examples:
  fleet status                          the running daemon's phase, e-stop and robots
  fleet status --config fleet.toml --json
""",
    "estop": """examples:
  fleet estop --reason "person in the room"   stop every robot; wait for each to confirm
  fleet estop --config fleet.toml --json --timeout 5
""",
    "resume": """examples:
  fleet resume                                release the e-stop once the room is clear
  fleet resume --config lab/secure.toml --user operator --password-file lab/secrets/operator.pw
""",
}


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
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
    from controller import wire
    from controller.cli import emit_json
    from controller.config import load_config, operator_identity
    from controller.io.bus import BusError
    from controller.runtime.estop import open_tool_session

    cfg = load_config(args.config)
    identity = operator_identity(cfg, args.user, args.password_file)
    word = args._words[-1]
    connect = args.connect or list(cfg.zenoh.listen)
    source = f"{getpass.getuser()}@{socket.gethostname()}"
    try:
        # with zenoh.estop_listen: the hub's path and the daemon's second at once
        session, bus = open_tool_session(cfg, identity, connect, two_paths=True)
    except BusError as exc:
        if args.json:
            extra = {}
            if word in ("estop", "resume"):
                extra = {
                    "command": word,
                    "engaged": word == "estop",
                    "confirmed": False,
                    "phase": None,
                    "agents_missing": list(cfg.robot_ids),
                }
            emit_json({"ok": False, "error": f"no daemon answered: {exc}", **extra})
        print(
            f"fleet {word}: no daemon of fleet {cfg.fleet.name!r} answered: {exc}", file=sys.stderr
        )
        return 1
    with session:
        if word in ("estop", "resume"):
            from controller.runtime.estop import describe_put, exit_status, put_estop

            result = put_estop(bus, cfg, word, source, getattr(args, "reason", ""), args.timeout)
            if args.json:
                emit_json(result)
            else:
                print(describe_put(word, result))
            return exit_status(result)
        replies = bus.query("status", wire.FleetStatus, timeout=args.timeout)
        if not replies:
            if args.json:
                emit_json({"ok": False, "error": "no daemon answered"})
            print(
                f"fleet status: no daemon of fleet {cfg.fleet.name!r} answered on {connect}",
                file=sys.stderr,
            )
            return 1
        from controller.runtime.claim import newest_status
        from controller.runtime.estop import holder_states

        st = newest_status(replies)
        others = sorted({r.controller for r in replies} - {st.controller})
        holders = holder_states(bus, min(0.5, args.timeout))
        not_kept = sorted({k for k, h in holders if h["durable"] is False})
        if args.json:
            emit_json(
                {
                    "ok": True,
                    **wire.to_dict(st),
                    "controllers": [st.controller, *others],
                    "estop_durable": not not_kept,
                    "estop_not_durable": not_kept,
                    "estop_holders": [h | {"holder": k} for k, h in holders],
                }
            )
        else:
            unknown = st.counters.get("estop_unknown")
            latch = "UNKNOWN (stopped)" if unknown else ("ENGAGED" if st.estop else "off")
            print(
                f"fleet {st.fleet}: phase {st.phase}, e-stop {latch}"
                f" (controller {st.controller or 'unnamed'})"
            )
            if not_kept:
                print(f"  E-STOP NOT DURABLE: {', '.join(not_kept)} cannot keep the latch")
            if others:
                print(f"  MORE THAN ONE CONTROLLER ANSWERED: also {', '.join(others)}")
            for r in st.robots:
                print(
                    f"  {r['id']}: {'present' if r['present'] else 'absent'}"
                    f"{', LINK LOST' if r.get('link_lost') else ''}"
                    f"{', SKEWED: its clock is off, its poses dropped' if r.get('skewed') else ''}"
                )
        return 0
