"""``fleet estop`` / ``fleet resume``: the e-stop put straight to the agents, and confirmed.

The ``EStop`` goes out on ``estop`` (every agent, the hub and the controller subscribe); then
every holder of the latch is asked (``estop/state/<role>/<id>``, QueryTarget.ALL, replies read
as they come so a hung daemon costs nothing) until each known agent (the config's robots and
every robot liveliness token) answers with the new state. An unconfirmed e-stop is put again
every ``REPUT`` s (it is latched: a repeat is harmless). Nothing here waits for the daemon.
"""

from __future__ import annotations

import time
from typing import Any

from controller import wire
from controller.config import FleetConfig

REPUT = 0.25  # s between repeats of an unconfirmed e-stop


def put_estop(
    bus, cfg: FleetConfig, word: str, source: str, reason: str, timeout: float
) -> dict[str, Any]:
    """Engage (``word`` "estop") or release ("resume") and wait at most ``timeout`` s for the
    confirmations. Returns the ``--json`` object (``confirmed``: every known agent did)."""
    engaged = word == "estop"
    msg = wire.EStop(t=time.time(), engaged=engaged, source=source, reason=reason)
    t0 = time.monotonic()
    deadline = t0 + timeout
    pub = bus.publisher("estop")
    tokens: list[str] = []  # robot liveliness tokens, appended as the replies come
    bus.alive_ids_async("robot", tokens, timeout=min(1.0, timeout))
    while not pub.matching() and time.monotonic() < deadline:
        time.sleep(0.005)  # polling for the subscribers' declarations (a handshake)
    pub.put(msg)
    sent = time.monotonic()
    known = set(cfg.robot_ids)
    agents, holders, elapsed = _confirmations(bus, msg, known, tokens, deadline, pub, t0)
    known |= set(tokens[:])
    status = None
    for _, st in bus.query_replies(bus.key("status"), wire.FleetStatus, timeout=0.3):
        status = st
        break
    missing = sorted(known - agents)
    return {
        "command": word,
        "engaged": engaged,
        "confirmed": not missing,
        "phase": status.phase if status else None,
        "agents_confirmed": sorted(agents),
        "agents_missing": missing,
        "known_agents": sorted(known),
        "daemon_confirmed": "controller" in holders,
        "hub_confirmed": "hub" in holders,
        "elapsed_s": None if missing or elapsed is None else round(elapsed, 4),
        "sent_after_s": round(sent - t0, 4),
    }


def _confirmations(
    bus, msg: wire.EStop, config: set[str], tokens: list[str], deadline: float, pub, t0: float
):
    """Ask every latch holder until every known agent (the ``config``'s robots and the robot
    ``tokens`` seen so far, which the liveliness look-up fills meanwhile) holds ``msg``'s state
    (stamped no older) or the deadline. Returns (agents that confirmed, roles of the other
    holders that did, seconds from ``t0`` to the last agent's confirmation or None)."""
    agents: set[str] = set()
    holders: set[str] = set()
    elapsed = None
    next_put = time.monotonic() + REPUT
    known = config | set(tokens[:])
    while time.monotonic() < deadline and not known <= agents:
        left = deadline - time.monotonic()
        for key, st in bus.query_replies(bus.estop_wildcard(), wire.EStop, min(0.3, left)):
            parsed = wire.parse_key(key, bus.fleet)
            if parsed is None or st.engaged != msg.engaged or st.t < msg.t:
                continue
            if parsed.parts.get("role") == "robot":
                agents.add(parsed.id)
            else:
                holders.add(parsed.parts.get("role", ""))
            known = config | set(tokens[:])
            if known <= agents:
                elapsed = time.monotonic() - t0
                break
        known = config | set(tokens[:])
        if not known <= agents and time.monotonic() >= next_put:
            pub.put(msg)
            next_put = time.monotonic() + REPUT
        if not known <= agents:
            time.sleep(0.005)  # between rounds of a poll (each round is a real check)
    return agents, holders, elapsed
