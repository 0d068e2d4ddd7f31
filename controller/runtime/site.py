"""``fleet router``: a site's zenoh router, serving several fleets on one zenoh network.

Zenoh's own router (the eclipse-zenoh package's session in router mode, no relay of ours): a
router per host, the host's processes connecting to it on loopback, the routers linked to each
other (``connect``) across the site's network. Each fleet keeps its own key space
(``fleet/<fleet.name>/...``), its own daemon and hub; an operator reaches every fleet through
the routers (``fleet estop --config A --config B``).

Security: the router the robots connect to checks who connects and what they may do. Given the
fleets' configs, it checks the union of their password dictionaries (plus ``extra``
dictionaries: the other routers' users) and applies every fleet's lab ACL profile side by side
(:func:`controller.config.acl.site_acl`): a robot of fleet A may put and receive only its own
keys of fleet A. The site's other routers connect to it as ``backbone`` users, which may do
everything (they carry daemons' and operators' traffic; place them where only trusted processes
reach them, e.g. listening on loopback). Zenoh's username authentication tells the listening
side who connected, not the other way round, so a router enforces the ACL on the links it
accepted; the links it opened carry no username.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from controller.config import ConfigError, FleetConfig, ZenohIdentity
from controller.config.acl import site_acl
from controller.config.sections import ZenohSection

log = logging.getLogger(__name__)

WATCH_EVERY = 0.5  # s between looks at the router's links (said when they change)


def merged_dictionary(paths: Sequence[str], out: Path) -> int:
    """Write the union of usrpwd dictionaries (``user:password`` lines) to ``out`` (mode 0600);
    returns the number of users. ConfigError when one user has two passwords."""
    users: dict[str, tuple[str, str]] = {}
    for path in paths:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError("", "zenoh.auth_dictionary", f"cannot read {path}: {exc}") from exc
        for line in text.splitlines():
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            user, sep, password = line.partition(":")
            if not sep:
                raise ConfigError("", "zenoh.auth_dictionary", f"{path}: not user:password")
            if user in users and users[user][0] != password:
                raise ConfigError(
                    "",
                    "zenoh.auth_dictionary",
                    f"user {user!r} has another password in {users[user][1]} than in {path}: "
                    "one identity per user across the site",
                )
            users[user] = (password, path)
    fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.writelines(f"{u}:{p}\n" for u, (p, _) in users.items())
    return len(users)


def site_section(
    cfgs: Sequence[FleetConfig], dictionary: str, backbone: Sequence[str]
) -> ZenohSection:
    """The ``[zenoh]`` section the router's session is built from: the first fleet's (TLS and
    limits), the merged dictionary and the site ACL when the fleets use the lab profile. A
    fleet with its own ACL file cannot be merged (ConfigError naming its key)."""
    if not cfgs:
        return ZenohSection(auth_dictionary=dictionary)
    first = cfgs[0].zenoh
    profiled = [c for c in cfgs if c.zenoh.acl_block]
    for c in cfgs:
        if c.zenoh.acl and not c.zenoh.acl_block:
            raise ConfigError(
                c.source,
                "zenoh.acl",
                "a site router merges the fleets' 'lab' profile only; a fleet with its own ACL "
                "file needs a router of its own",
            )
    if profiled and len(profiled) != len(cfgs):
        bare = next(c for c in cfgs if not c.zenoh.acl_block)
        raise ConfigError(
            bare.source,
            "zenoh.acl",
            "every fleet of a secured site router needs the 'lab' ACL profile (this one has "
            "none: its robots would be refused everything)",
        )
    block = json.dumps(site_acl(list(cfgs), tuple(backbone))) if profiled else ""
    return replace(
        first,
        auth_dictionary=dictionary,
        acl="lab" if block else "",
        acl_block=block,
        user="",
        password="",
        password_file="",
    )


def run_router(
    cfgs: Sequence[FleetConfig],
    listen: Sequence[str],
    connect: Sequence[str],
    stop: threading.Event,
    *,
    backbone: Sequence[str] = (),
    extra_dictionaries: Sequence[str] = (),
    identity: ZenohIdentity | None = None,
    duration: float = 0.0,
) -> int:
    """Serve until ``stop`` (or ``duration`` s). Exit 0; 1 when zenoh cannot listen there."""
    from controller.io.bus import Bus, BusError

    dicts = [c.zenoh.auth_dictionary for c in cfgs if c.zenoh.auth_dictionary]
    dicts += list(extra_dictionaries)
    with tempfile.TemporaryDirectory(prefix="fleet-router-") as tmp:
        users = 0
        path = ""
        if dicts:
            path = str(Path(tmp) / "users.txt")
            users = merged_dictionary(dicts, Path(path))
        section = site_section(cfgs, path, backbone)
        try:
            bus = Bus(
                section,
                "site",
                mode="router",
                listen=list(listen),
                connect=list(connect),
                identity=identity or ZenohIdentity("--user"),
            )
        except BusError as exc:
            print(f"fleet router: {exc}", file=sys.stderr)
            return 1
        fleets = ", ".join(c.fleet.name for c in cfgs) or "any"
        guard = (
            f"{users} users, the fleets' ACL"
            + (f", backbone {', '.join(backbone)}" if backbone else "")
            if section.acl_block
            else (f"{users} users" if users else "open")
        )
        print(
            f"fleet router: fleets {fleets} on {list(listen)}"
            + (f", linking to {list(connect)}" if connect else "")
            + f" ({guard})",
            file=sys.stderr,
            flush=True,
        )
        try:
            t0 = time.monotonic()
            seen: set[str] = set()
            while not stop.is_set():
                now = set(bus.routers())
                for zid in sorted(now - seen):
                    print(f"fleet router: linked to router {zid}", file=sys.stderr, flush=True)
                for zid in sorted(seen - now):
                    print(f"fleet router: lost router {zid}", file=sys.stderr, flush=True)
                seen = now
                if duration and time.monotonic() - t0 >= duration:
                    break
                stop.wait(WATCH_EVERY)
        finally:
            bus.close()
    print("fleet router: stopped", file=sys.stderr)
    return 0
