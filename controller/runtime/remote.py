"""``fleet status|estop|resume`` for one fleet or a site's fleets at once (the command line is
controller/commands/remote.py): each fleet through its own config's endpoints and identity, the
fleets in parallel threads, a site's answer the worst of theirs."""

from __future__ import annotations

import getpass
import socket
import threading
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Answer:
    """One fleet's outcome: exit status, its --json object and its text (stdout, stderr)."""

    code: int
    obj: dict[str, Any]
    out: list[str] = field(default_factory=list)
    err: list[str] = field(default_factory=list)


def act(cfgs: list, word: str, args) -> Answer:
    """``word`` ("status", "estop", "resume") on each fleet of ``cfgs`` at once; one fleet's
    answer as it is, several as the site's (:func:`_site`). ``args``: the command's options
    (``user``, ``password_file``, ``connect``, ``timeout``, ``reason``)."""
    if len(cfgs) == 1:
        return _one(cfgs[0], args, word)
    answers: list[Answer | None] = [None] * len(cfgs)

    def one(i: int) -> None:
        try:
            answers[i] = _one(cfgs[i], args, word)
        except Exception as exc:  # noqa: BLE001 - one fleet's failure is that fleet's line
            answers[i] = Answer(1, {"ok": False, "error": str(exc)}, err=[str(exc)])

    threads = [threading.Thread(target=one, args=(i,)) for i in range(len(cfgs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return _site(word, cfgs, [x for x in answers if x is not None])


def _site(word: str, cfgs: list, answers: list[Answer]) -> Answer:
    """The site's answer from each fleet's: the worst exit status, a verdict line first."""
    code = max(a.code for a in answers)
    fleets = [{"fleet": c.fleet.name, **a.obj} for c, a in zip(cfgs, answers, strict=True)]
    obj: dict[str, Any] = {"ok": code == 0, "fleets": fleets}
    lines: list[str] = []
    if word in ("estop", "resume"):
        missing = [f"{f['fleet']}/{r}" for f in fleets for r in f.get("agents_missing", ())]
        confirmed = all(f.get("confirmed") for f in fleets)
        obj |= {
            "command": word,
            "engaged": word == "estop",
            "confirmed": confirmed,
            "agents_missing": missing,
        }
        what = "e-stop ENGAGED" if word == "estop" else "e-stop released"
        if confirmed:
            lines.append(f"site: {what} on {len(fleets)} fleets, confirmed by every agent")
        else:
            lines.append(
                f"site: {what} on {len(fleets)} fleets; NOT confirmed by "
                f"{', '.join(missing) or 'a fleet (see its line)'}"
            )
    else:
        up = [f["fleet"] for f in fleets if f.get("ok")]
        down = [f["fleet"] for f in fleets if not f.get("ok")]
        lines.append(
            f"site: {len(up)} of {len(fleets)} fleets answered"
            + (f"; NO DAEMON ANSWERED for {', '.join(down)}" if down else "")
        )
    err: list[str] = []
    for c, a in zip(cfgs, answers, strict=True):
        lines += [f"[{c.fleet.name}] {line}" for line in a.out]
        err += [f"[{c.fleet.name}] {line}" for line in a.err]
    return Answer(code, obj, lines, err)


def _one(cfg, args, word: str) -> Answer:
    """One fleet's status, e-stop or resume (what ``fleet WORD --config F`` does)."""
    from controller import wire
    from controller.config import operator_identity
    from controller.io.bus import BusError
    from controller.runtime.estop import open_tool_session

    identity = operator_identity(cfg, args.user, args.password_file)
    connect = args.connect or list(cfg.zenoh.listen)
    source = f"{getpass.getuser()}@{socket.gethostname()}"
    try:
        # with zenoh.estop_listen: the hub's path and the daemon's second at once
        session, bus = open_tool_session(cfg, identity, connect, two_paths=True)
    except BusError as exc:
        extra = {}
        if word in ("estop", "resume"):
            extra = {
                "command": word,
                "engaged": word == "estop",
                "confirmed": False,
                "phase": None,
                "agents_missing": list(cfg.robot_ids),
            }
        return Answer(
            1,
            {"ok": False, "error": f"no daemon answered: {exc}", **extra},
            err=[f"fleet {word}: no daemon of fleet {cfg.fleet.name!r} answered: {exc}"],
        )
    with session:
        if word in ("estop", "resume"):
            from controller.runtime.estop import describe_put, exit_status, put_estop

            result = put_estop(bus, cfg, word, source, getattr(args, "reason", ""), args.timeout)
            return Answer(exit_status(result), result, [describe_put(word, result)])
        replies = bus.query("status", wire.FleetStatus, timeout=args.timeout)
        if not replies:
            return Answer(
                1,
                {"ok": False, "error": "no daemon answered"},
                err=[f"fleet status: no daemon of fleet {cfg.fleet.name!r} answered on {connect}"],
            )
        from controller.runtime.claim import newest_status
        from controller.runtime.estop import holder_states

        st = newest_status(replies)
        others = sorted({r.controller for r in replies} - {st.controller})
        holders = holder_states(bus, min(0.5, args.timeout))
        not_kept = sorted({k for k, h in holders if h["durable"] is False})
        obj = {
            "ok": True,
            **wire.to_dict(st),
            "controllers": [st.controller, *others],
            "estop_durable": not not_kept,
            "estop_not_durable": not_kept,
            "estop_holders": [h | {"holder": k} for k, h in holders],
        }
        unknown = st.counters.get("estop_unknown")
        latch = "UNKNOWN (stopped)" if unknown else ("ENGAGED" if st.estop else "off")
        out = [
            f"fleet {st.fleet}: phase {st.phase}, e-stop {latch}"
            f" (controller {st.controller or 'unnamed'})"
        ]
        if not_kept:
            out.append(f"  E-STOP NOT DURABLE: {', '.join(not_kept)} cannot keep the latch")
        if others:
            out.append(f"  MORE THAN ONE CONTROLLER ANSWERED: also {', '.join(others)}")
        for r in st.robots:
            out.append(
                f"  {r['id']}: {'present' if r['present'] else 'absent'}"
                f"{', LINK LOST' if r.get('link_lost') else ''}"
                f"{', SKEWED: its clock is off, its poses dropped' if r.get('skewed') else ''}"
            )
        return Answer(0, obj, out)
