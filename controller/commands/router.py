"""``fleet router [--config F ...] --listen EP [--connect EP] [--backbone USER]``: a site's
zenoh router, serving several fleets on one zenoh network.

Zenoh's own router (the eclipse-zenoh package in router mode): run one per host of a site, the
host's daemons, agents and tools connecting to it on loopback (their config's
``zenoh.listen``), the routers linked across the site's network (``--connect``). Each fleet
keeps its key space, its daemon and its hub; ``fleet status|estop|resume --config A --config B``
reach every fleet at once. Given the fleets' configs (``--config``, once per fleet), the router
checks the union of their password dictionaries and applies each fleet's lab ACL profile side
by side: a robot of one fleet may not put or receive another fleet's keys. Routers of the site
that connect to this one authenticate as ``--backbone`` users (in an ``--auth-dictionary``)
and may do everything; a router connects to another as ``--user``/``--password-file``, and
then checks everyone who connects to it (zenoh refuses a session without a password it can
check): give it their dictionaries (``--auth-dictionary``; the fleets' ACL is applied by the
router the robots connect to). Stops
on SIGINT/SIGTERM; exit 1 when zenoh cannot listen, 2 on a bad config or argument.
"""

from __future__ import annotations

EXAMPLES = """examples:
  fleet router --config cell_a.toml --config cell_b.toml --listen tcp/127.0.0.1:7447 \\
      --listen tcp/10.0.0.5:7447 --auth-dictionary site_users.txt --backbone site
                                  the robots' router: both fleets' users and ACL
  fleet router --listen tcp/127.0.0.1:7447 --connect tcp/10.0.0.5:7447 \\
      --user site --password-file site.pw --auth-dictionary cell_a_users.txt \
      --auth-dictionary cell_b_users.txt
                                  the control room's router, linked to it as a backbone
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument(
        "--config",
        action="append",
        default=[],
        help="a fleet's config, once per fleet the router serves (their users and ACL)",
    )
    parser.add_argument(
        "--listen",
        action="append",
        default=[],
        help="zenoh endpoint to listen on (default: the first config's zenoh.listen)",
    )
    parser.add_argument(
        "--connect", action="append", default=[], help="another router of the site to link to"
    )
    parser.add_argument(
        "--backbone",
        action="append",
        default=[],
        help="user name of a router that connects to this one: may do everything",
    )
    parser.add_argument(
        "--auth-dictionary",
        action="append",
        default=[],
        help="more user:password lines to accept (the backbone routers')",
    )
    parser.add_argument("--user", help="zenoh user this router authenticates as when it connects")
    parser.add_argument("--password-file", help="file holding --user's password")
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")


def run(args) -> int:
    from pathlib import Path

    from controller.commands import distinct_fleets, stop_on_signals
    from controller.config import InputError, ZenohIdentity, load_config
    from controller.runtime.site import run_router

    cfgs = [load_config(p) for p in args.config]
    distinct_fleets(cfgs)
    listen = args.listen or (list(cfgs[0].zenoh.listen) if cfgs else [])
    if not listen:
        raise InputError("--listen: where should the router listen? (or give a --config)")
    if bool(args.user) != bool(args.password_file):
        raise InputError("--user and --password-file go together")
    for p in [*args.auth_dictionary, *([args.password_file] if args.password_file else [])]:
        if not Path(p).is_file():
            raise InputError(f"no such file: {p}")
    if args.user and not (args.auth_dictionary or any(c.zenoh.auth_dictionary for c in cfgs)):
        raise InputError(
            "--user: a zenoh session that authenticates refuses everyone who connects to it "
            "without a password it can check: give --auth-dictionary (or the fleets' configs)"
        )
    if args.backbone and not any(c.zenoh.acl_block for c in cfgs):
        raise InputError("--backbone: the router applies no ACL (give the fleets' secured configs)")
    identity = ZenohIdentity(
        "--user",
        user=args.user or "",
        password_file=str(Path(args.password_file).resolve()) if args.password_file else "",
    )
    return run_router(
        cfgs,
        listen,
        args.connect,
        stop_on_signals(),
        backbone=tuple(args.backbone),
        extra_dictionaries=args.auth_dictionary,
        identity=identity,
        duration=args.duration,
    )
