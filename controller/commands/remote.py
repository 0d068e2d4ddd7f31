"""``fleet status|estop|resume [--config F] [--json]``: talk to a running daemon over the bus.

``status`` queries the daemon's status queryable. ``estop`` publishes a latched emergency stop
(every agent stops its robot and refuses commands until ``resume``); both then query the status
to confirm the daemon saw it. Exit 1 when no daemon answers.
"""

from __future__ import annotations

import getpass
import socket
import sys
import time

from controller.commands import add_config_argument


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
    from controller.io.bus import Bus, BusError

    cfg = load_config(args.config)
    identity = operator_identity(cfg, args.user, args.password_file)
    word = args._words[-1]
    connect = args.connect or list(cfg.zenoh.listen)
    source = f"{getpass.getuser()}@{socket.gethostname()}"
    try:
        bus = Bus(
            cfg.zenoh,
            cfg.fleet.name,
            mode="client",
            listen=[],
            connect=connect,
            identity=identity,
        )
    except BusError as exc:
        if args.json:
            emit_json({"ok": False, "error": f"no daemon answered: {exc}"})
        print(
            f"fleet {word}: no daemon of fleet {cfg.fleet.name!r} answered: {exc}", file=sys.stderr
        )
        return 1
    with bus:
        if word in ("estop", "resume"):
            engaged = word == "estop"
            msg = wire.EStop(
                t=time.time(), engaged=engaged, source=source, reason=getattr(args, "reason", "")
            )
            pub = bus.publisher("estop")
            deadline = time.monotonic() + args.timeout
            while not pub.matching() and time.monotonic() < deadline:
                time.sleep(0.01)  # polling for the subscribers' declarations (a handshake)
            pub.put(msg)
            # confirm: the daemon's status shows the new state
            status = None
            while time.monotonic() < deadline:
                replies = bus.query(
                    "status", wire.FleetStatus, timeout=max(0.1, deadline - time.monotonic())
                )
                if replies and replies[0].estop == engaged:
                    status = replies[0]
                    break
                time.sleep(0.05)
            result = {
                "command": word,
                "engaged": engaged,
                "confirmed": status is not None,
                "phase": status.phase if status else None,
            }
            if args.json:
                emit_json(result)
            else:
                state = "confirmed by the daemon" if status else "NOT confirmed (no daemon?)"
                print(f"fleet {word}: sent, {state}")
            return 0 if status is not None else 1
        replies = bus.query("status", wire.FleetStatus, timeout=args.timeout)
        if not replies:
            if args.json:
                emit_json({"ok": False, "error": "no daemon answered"})
            print(
                f"fleet status: no daemon of fleet {cfg.fleet.name!r} answered on {connect}",
                file=sys.stderr,
            )
            return 1
        st = replies[0]
        if args.json:
            emit_json({"ok": True, **wire.to_dict(st)})
        else:
            print(f"fleet {st.fleet}: phase {st.phase}, e-stop {'ENGAGED' if st.estop else 'off'}")
            for r in st.robots:
                print(
                    f"  {r['id']}: {'present' if r['present'] else 'absent'}"
                    f"{', LINK LOST' if r.get('link_lost') else ''}"
                )
        return 0
