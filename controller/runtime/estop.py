"""``fleet estop`` / ``fleet resume``: the e-stop put straight to the agents, and confirmed;
and the latch's file (the controller side's only e-stop I/O besides the bus).

The ``EStop`` goes out on ``estop`` (every agent, the hub and the controller subscribe) with the
next ``epoch``: one above the greatest any holder answers (``controller.latch`` refuses a release
at or below the epoch it holds). Then every holder of the latch is asked
(``estop/state/<role>/<id>``, QueryTarget.ALL, replies read as they come so a hung daemon costs
nothing) until each known agent (the config's robots and every robot liveliness token) answers
with the new state at that epoch or above. An unconfirmed e-stop is put again every ``REPUT`` s
(it is latched: a repeat is harmless), one epoch above any holder that refused it. Nothing here
waits for the daemon.

``LatchFile``: the hub and the daemon each keep their latch in
``<state folder>/estop-<fleet>-<holder>.json`` (``state_folder``: ``fleet.state_dir``, else the
older ``log.state_dir``, else ``state/`` beside the config file; written to a temporary file,
fsynced, renamed over the old one, folder fsynced) and read it back at start: a restarted hub or
daemon, and a full restart, come up with the latch they left. A file that is missing or
unreadable leaves the latch unknown (stopped); a file only in the old default place (the log
folder) is read once (the latch is then written to the new place).

Durability: a holder whose latch could not be written answers ``durable: false``; the tool waits
(up to its timeout) for every hub and controller that answers to hold the new state *durably*,
and reports ``durable: false`` with the holders (``not_durable``) otherwise, exit 3 (``EXIT``).
A release is not put at all while a holder answers ``durable: false`` (``refused``), and the
holder itself refuses one meanwhile (``controller.latch``).

Epochs: robots' answers are believed only up to ``EPOCH_SLACK`` above the hub's and controller's
greatest epoch (without them, the least robot epoch): one robot's credentials answering an
engage at 2^63-1 cannot push a release out of the encodable range.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from pathlib import Path
from typing import Any

from controller import wire
from controller.config import FleetConfig

log = logging.getLogger(__name__)

EPOCH_WAIT = 0.3  # s: how long the tool gathers the holders' epochs before it puts
REPUT = 0.25  # s between repeats of an unconfirmed e-stop
# s a live daemon (its liveliness token seen) is waited for after every agent confirmed: a daemon
# slow to answer on a loaded machine is still counted (its durability with it); a hung one delays
# the tool no longer than this
DAEMON_GRACE = 1.0
# how far above the trusted holders' greatest epoch a robot's answer is believed: the operator
# releases an honest agent may have seen that a restarted hub and daemon missed (each release
# is one operator's ``fleet resume``; 64 of them while both were down is not a lab's day)
EPOCH_SLACK = 64
TRUSTED = ("hub", "controller")
# exit status of fleet estop|resume: every agent confirmed and every holder durable; some agent
# did not confirm (or nothing answered); every agent confirmed but a holder cannot keep the state
# (or a release was refused for that reason)
EXIT = {"confirmed": 0, "unconfirmed": 1, "not_durable": 3}


def put_estop(
    bus, cfg: FleetConfig, word: str, source: str, reason: str, timeout: float
) -> dict[str, Any]:
    """Engage (``word`` "estop") or release ("resume") and wait at most ``timeout`` s for the
    confirmations. Returns the ``--json`` object (``confirmed``: every known agent did)."""
    engaged = word == "estop"
    t0 = time.monotonic()
    deadline = t0 + timeout
    pub = bus.publisher("estop")
    tokens: list[str] = []  # robot liveliness tokens, appended as the replies come
    bus.alive_ids_async("robot", tokens, timeout=min(1.0, timeout))
    daemons: list[str] = []  # the daemons' tokens: a live daemon is a holder to wait for
    bus.alive_ids_async("controller", daemons, timeout=min(1.0, timeout))
    known = set(cfg.robot_ids)
    # an engage goes out at once (any epoch latches, at the holder's own epoch or above); a
    # release must exceed every holder's epoch, and is not put while a holder cannot keep it:
    # ask them first
    bound = wire.MAX_SEQ - 1
    epoch = 0
    if not engaged:
        before = holder_states(bus, min(EPOCH_WAIT, timeout / 3))
        epoch, bound = release_epoch(before)
        not_kept = sorted(h for h, st in before if st.get("durable") is False)
        if not_kept:
            return {
                **_result(word, engaged, set(), set(), known | set(tokens[:]), None, None),
                "refused": "a latch holder cannot keep its state (durable: false)",
                "durable": False,
                "not_durable": not_kept,
                "holders": [h | {"holder": k} for k, h in before],
                "epoch": epoch - 1,
                "sent_after_s": None,
            }
    msg = wire.EStop(t=time.time(), engaged=engaged, source=source, reason=reason, epoch=epoch)
    while not pub.matching() and time.monotonic() < deadline:
        time.sleep(0.005)  # polling for the subscribers' declarations (a handshake)
    pub.put(msg)
    sent = time.monotonic()
    g = _Gather(msg, known, tokens, t0, bound, daemons)
    _confirmations(bus, g, deadline, pub)
    known |= set(tokens[:])
    status = None
    for _, st in bus.query_replies(bus.key("status"), wire.FleetStatus, timeout=0.3):
        status = st
        break
    out = _result(word, engaged, g.agents, g.holders, known, status, g.elapsed)
    not_kept = sorted(g.not_durable())
    return {
        **out,
        "sent_after_s": round(sent - t0, 4),
        "epoch": g.epoch,
        "durable": not not_kept,
        "not_durable": not_kept,
        "holders": g.holder_list(),
    }


# s: the hub's handshake ``fleet estop`` waits for on its own (zenoh's default is 10 s: a hung
# hub cost the tool that much before it put anything); the second path does not wait for it
TOOL_OPEN_S = 2.0


class ToolPaths:
    """``fleet estop|resume``'s sessions with ``zenoh.estop_listen`` set: the hub's (a client of
    ``connect``) and the daemon's second listener's (a client too: a router passes a peer's
    queries on to other peers only when they are linked, so the agents, peers there, would not
    answer a peer tool), opened at once, each in a thread. Entering returns as soon as one is
    open (a ``controller.io.bus.Paths``; the other joins when it opens); BusError when none
    does. Leaving closes both (a hung hub's handshake fails after ``TOOL_OPEN_S``)."""

    def __init__(self, cfg: FleetConfig, identity, connect: list[str]) -> None:
        import threading

        from controller.io.bus import Bus, Paths

        self.paths = Paths(cfg.fleet.name)
        self._errors: list[Exception] = []
        self._cond = threading.Condition()
        self._opened: list[Bus] = []
        ways = [
            dict(mode="client", connect=connect, open_timeout_s=TOOL_OPEN_S),
            dict(mode="client", connect=list(cfg.zenoh.estop_listen), open_timeout_s=1.0),
        ]

        def open_one(way: dict) -> None:
            try:
                bus = Bus(cfg.zenoh, cfg.fleet.name, listen=[], identity=identity, **way)
            except Exception as exc:  # noqa: BLE001 - said by __enter__ when none opens
                with self._cond:
                    self._errors.append(exc)
                    self._cond.notify_all()
                return
            with self._cond:
                self._opened.append(bus)
                self.paths.add(bus)
                self._cond.notify_all()

        self._threads = [threading.Thread(target=open_one, args=(w,), daemon=True) for w in ways]
        for t in self._threads:
            t.start()

    def __enter__(self):
        from controller.io.bus import BusError

        with self._cond:
            self._cond.wait_for(lambda: self._opened or len(self._errors) == len(self._threads))
            if not self._opened:
                raise BusError("; ".join(str(e) for e in self._errors))
        return self.paths

    def __exit__(self, *exc: object) -> None:
        for t in self._threads:
            t.join()
        for bus in self._opened:
            bus.close()


def open_tool_session(cfg: FleetConfig, identity, connect: list[str], two_paths: bool):
    """A command-line tool's session and the bus it talks through (``fleet estop|resume|
    status``): with ``two_paths`` and ``zenoh.estop_listen`` set, both paths (``ToolPaths``);
    else a client of ``connect``. Raises BusError when nothing opens."""
    from controller.io.bus import Bus

    if two_paths and cfg.zenoh.estop_listen:
        session = ToolPaths(cfg, identity, connect)
        return session, session.__enter__()
    z = cfg.zenoh
    bus = Bus(z, cfg.fleet.name, mode="client", listen=[], connect=connect, identity=identity)
    return bus, bus


def describe_put(word: str, result: dict[str, Any]) -> str:
    """``fleet estop|resume``'s text: confirmed or not, and whether every holder keeps it."""
    missing = result["agents_missing"]
    if result.get("refused"):
        return (
            f"fleet {word}: REFUSED, nothing sent: {', '.join(result['not_durable'])} cannot "
            "keep the e-stop latch (durable: false); free its state folder first"
        )
    if missing:
        text = (
            f"fleet {word}: sent; NOT confirmed by {', '.join(missing)} (confirmed by "
            f"{', '.join(result['agents_confirmed']) or 'no agent'})"
        )
        if word == "resume":
            text += (
                "\n  is each agent up (fleet status)? A holder also refuses a release stamped "
                "further than fleet.max_clock_skew from its clock: check this computer's clock "
                "against the robots' (NTP or chrony), and their logs"
            )
    else:
        text = (
            f"fleet {word}: confirmed by every agent "
            f"({', '.join(result['agents_confirmed'])}) in "
            f"{result['elapsed_s'] * 1e3:.0f} ms; daemon "
            f"{'too' if result['daemon_confirmed'] else 'not seen'}"
        )
    if not result.get("durable", True):
        text += (
            f"\n  NOT DURABLE: {', '.join(result['not_durable'])} cannot keep the e-stop latch "
            "in its state folder (its file holds an older state)"
        )
    return text


def exit_status(result: dict[str, Any]) -> int:
    """``fleet estop|resume``'s exit status for its result (``EXIT``)."""
    if result.get("refused"):
        return EXIT["not_durable"]
    if result["agents_missing"]:
        return EXIT["unconfirmed"]
    return EXIT["confirmed"] if result.get("durable", True) else EXIT["not_durable"]


def _result(word, engaged, agents, holders, known, status, elapsed) -> dict[str, Any]:
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
    }


def describe(st: wire.EStop) -> dict[str, Any]:
    """One holder's answer for ``--json``: its state, epoch, who set it, whether it is kept."""
    return {
        "engaged": st.engaged,
        "epoch": st.epoch,
        "source": st.source,
        "durable": st.durable,
    }


def holder_states(bus, timeout: float) -> list[tuple[str, dict[str, Any]]]:
    """Every latch holder's answer within ``timeout`` s as (``role/id``, ``describe``), in
    arrival order (two answers on one key - an impostor beside the agent - both listed)."""
    out = []
    for key, st in bus.query_replies(bus.estop_wildcard(), wire.EStop, timeout):
        parsed = wire.parse_key(key, bus.fleet)
        if parsed is not None:
            out.append((f"{parsed.parts.get('role', '')}/{parsed.id}", describe(st)))
    return out


def credible_bound(states: list[tuple[str, dict[str, Any]]]) -> int:
    """The greatest epoch a robot's answer is believed at (see the module doc)."""
    trusted = [h["epoch"] for k, h in states if k.split("/")[0] in TRUSTED]
    if trusted:
        ref = max(trusted)
    else:
        ref = min((h["epoch"] for _, h in states), default=0)
    return min(ref + EPOCH_SLACK, wire.MAX_SEQ - 1)


def release_epoch(states: list[tuple[str, dict[str, Any]]]) -> tuple[int, int]:
    """(the epoch a release goes out at: one above every credible holder's, the bound of a
    credible robot epoch)."""
    bound = credible_bound(states)
    best = 0
    for k, h in states:
        if k.split("/")[0] in TRUSTED or h["epoch"] <= bound:
            best = max(best, min(h["epoch"], wire.MAX_SEQ - 1))
    return best + 1, bound


def held_epoch(bus, timeout: float) -> int:
    """The greatest credible epoch any holder answers within ``timeout`` s (0 when none)."""
    return release_epoch(holder_states(bus, timeout))[0] - 1


def _confirmations(bus, g: _Gather, deadline: float, pub) -> None:
    """Ask every latch holder until every known agent (the config's robots and the robot
    tokens seen so far, which the liveliness look-up fills meanwhile) holds the put state
    (a release: at its epoch or above) and every other holder that answers at all (the hub, the
    daemon) holds it too, durably, or the deadline. A holder engaged at the release's epoch
    or above refused it: it is put again one epoch above (a credible epoch only). ``g`` then
    holds the agents that confirmed, the roles of the other holders that did, the seconds to
    the last agent's confirmation, the greatest epoch a confirmation named, each answer."""
    next_put = time.monotonic() + REPUT
    while time.monotonic() < deadline and not g.done():
        left = deadline - time.monotonic()
        for key, st in bus.query_replies(bus.estop_wildcard(), wire.EStop, min(0.3, left)):
            parsed = wire.parse_key(key, bus.fleet)
            if parsed is not None and g.take(parsed, st):  # refused: put it above
                pub.put(g.restamped())
                next_put = time.monotonic() + REPUT
            if g.done():
                break
        if not g.done() and time.monotonic() >= next_put:
            pub.put(g.restamped())
            next_put = time.monotonic() + REPUT
        if not g.done():
            time.sleep(0.005)  # between rounds of a poll (each round is a real check)


class _Gather:
    """The confirmations of one put, as the holders' replies come."""

    def __init__(
        self,
        msg: wire.EStop,
        config: set[str],
        tokens: list[str],
        t0: float,
        bound: int = wire.MAX_SEQ - 1,
        daemons: list[str] | None = None,
    ) -> None:
        self.msg, self.config, self.tokens, self.t0 = msg, config, tokens, t0
        self.daemons = daemons if daemons is not None else []  # live daemons' tokens, as seen
        self.bound = bound  # the greatest epoch a robot's refusal is believed at
        self.agents: set[str] = set()
        self.holders: set[str] = set()
        self.present: set[str] = set()  # the other holders' roles (hub, controller) that answer
        self.elapsed: float | None = None
        self.epoch = msg.epoch
        self.last: dict[str, wire.EStop] = {}  # the last answer of each other holder
        self.answers: dict[tuple[str, wire.EStop], None] = {}  # every distinct answer, in order

    def known(self) -> set[str]:
        return self.config | set(self.tokens[:])

    def restamped(self) -> wire.EStop:
        """The message to put again, stamped now (a holder refuses a release stamped further
        than the clocks' skew from its clock: an old one is a replay)."""
        self.msg = dataclasses.replace(self.msg, t=time.time())
        return self.msg

    def done(self) -> bool:
        if not (
            self.known() <= self.agents and self.present <= self.holders and not self.not_durable()
        ):
            return False
        # a live daemon that has not answered yet: waited for a grace after the last agent
        waiting = bool(self.daemons[:]) and "controller" not in self.present
        return not waiting or time.monotonic() - self.t0 - (self.elapsed or 0.0) > DAEMON_GRACE

    def not_durable(self) -> set[str]:
        """The other holders whose last answer says their state is not kept."""
        return {h for h, st in self.last.items() if not st.durable}

    def holder_list(self) -> list[dict[str, Any]]:
        """Each holder's answers (``--json`` ``holders``), the last of each distinct one."""
        return [describe(st) | {"holder": h} for h, st in self.answers]

    def take(self, parsed, st: wire.EStop) -> bool:
        """One holder's reply; True when it refused a release (``msg`` is now one above)."""
        role = parsed.parts.get("role", "")
        self.answers[(f"{role}/{parsed.id}", dataclasses.replace(st, t=0.0, seq=0))] = None
        trusted = role in TRUSTED
        if role != "robot":
            self.present.add(role)
            self.last[f"{role}/{parsed.id}"] = st
        if (
            not self.msg.engaged
            and st.engaged
            and st.epoch >= self.msg.epoch
            and (trusted or st.epoch <= self.bound)
            and st.epoch < wire.MAX_SEQ
        ):
            self.msg = dataclasses.replace(self.msg, epoch=st.epoch + 1)
            return True
        if st.engaged != self.msg.engaged or st.epoch < self.msg.epoch:
            return False
        if not trusted and st.epoch > self.bound:
            return False  # an impostor's answer: neither a confirmation nor a refusal
        if role == "robot":
            self.agents.add(parsed.id)
        elif st.durable:
            self.holders.add(role)
        else:
            self.holders.discard(role)
        self.epoch = max(self.epoch, st.epoch)
        if self.elapsed is None and self.known() <= self.agents:
            self.elapsed = time.monotonic() - self.t0
        return False


class LatchFile:
    """The latch kept in one small JSON file (an ``EStop``), replaced atomically."""

    def __init__(self, cfg: FleetConfig, holder: str) -> None:
        """``holder``: "hub" or "controller" (each keeps its own file)."""
        name = f"estop-{cfg.fleet.name}-{holder}.json"
        self.path = state_folder(cfg) / name
        # the default place before fleet.state_dir (the log folder), read when the new is empty
        self.legacy = None if cfg.log.state_dir else Path(cfg.log.dir) / name
        self.kept_at_start = False  # load_kept wrote the state it read

    def load(self) -> wire.EStop | None:
        """The latch last written, or None (no file, or unreadable: logged) - unknown."""
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            if self.legacy is not None and self.legacy.is_file():
                log.warning("e-stop latch read from its old place %s", self.legacy)
                return self._decode(self.legacy, self.legacy.read_bytes())
            log.warning("no e-stop latch file %s: the latch is unknown (stopped)", self.path)
            return None
        except OSError as exc:
            log.error("e-stop latch file %s unreadable (%s): the latch is unknown", self.path, exc)
            return None
        return self._decode(self.path, raw)

    def load_kept(self, holder: str) -> wire.EStop | None:
        """What a hub or daemon starts with: the latch last written (``load``), written again
        at once to prove the folder keeps it. When it does not (full disk, read-only or broken
        folder), the file may be stale - an engage since may have failed to reach it - so the
        holder starts *engaged* at the file's epoch (the most restrictive state; its keeper then
        answers ``durable: false`` and refuses releases until the folder keeps it again)."""
        msg = self.load()
        try:
            if msg is not None:
                self.save(msg)
            else:
                self.save_probe()
        except OSError as exc:
            self.kept_at_start = False
            log.error(
                "cannot keep the e-stop latch in %s (%s): starting ENGAGED, not durable, until "
                "the folder can be written",
                self.path,
                exc,
            )
            return wire.EStop(
                t=time.time(),
                engaged=True,
                source=f"{holder} (state folder not writable at start)",
                reason=f"cannot keep the e-stop latch: {exc}",
                epoch=0 if msg is None else msg.epoch,
            )
        self.kept_at_start = msg is not None
        return msg

    def save_probe(self) -> None:
        """Write and remove a temporary file where the latch goes (raises OSError)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "wb") as f:
            f.write(b"{}")
            f.flush()
            os.fsync(f.fileno())
        tmp.unlink()

    @staticmethod
    def _decode(path: Path, raw: bytes) -> wire.EStop | None:
        try:
            msg = wire.decode(wire.EStop, raw)
        except wire.WireError as exc:
            log.error("e-stop latch file %s is corrupt (%s): the latch is unknown", path, exc)
            return None
        if not isinstance(msg, wire.EStop):
            return None
        return dataclasses.replace(msg, durable=True)

    def save(self, msg: wire.EStop) -> None:
        """Write ``msg``: a temporary file, fsync, rename over the old one, fsync the folder."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "wb") as f:
            f.write(wire.encode(msg))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        fd = os.open(self.path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def state_folder(cfg: FleetConfig) -> Path:
    """Where the hub and the daemon keep the latch: ``fleet.state_dir`` (relative to the config
    file's folder), else ``log.state_dir`` (the older key, as it was), else ``state/`` beside the
    config file (in-process configs: beside ``log.dir``)."""
    source = Path(cfg.source) if cfg.source else None
    base = source.parent if source is not None and source.is_file() else Path(cfg.log.dir).parent
    if cfg.fleet.state_dir:
        return base / cfg.fleet.state_dir  # an absolute path stays itself
    if cfg.log.state_dir:
        return Path(cfg.log.state_dir)
    return base / "state"


class LatchKeeper:
    """Writes a latch to its ``LatchFile`` whenever it changed (``poll`` from a loop thread,
    never from a zenoh callback), and tells the latch (``Latch.mark_saved``) so that it answers
    ``durable: false`` while a state is not in its file. A failed write is logged at once and
    retried every poll (logged again when it heals or fails anew)."""

    RETRY = 0.5  # s between writes of a state that failed (a new state is tried at once)

    def __init__(self, latch, file: LatchFile) -> None:
        self.latch, self.file = latch, file
        self._tried = -2
        kept = file.kept_at_start or latch.state() is None
        self.saved = latch.version if kept else -1
        self._failing = False
        self._retry_at = 0.0
        self.failures = 0
        latch.mark_saved(self.saved, ok=True)
        self.poll()  # the state it starts with (read from the file, or an old place) kept now

    def poll(self) -> bool:
        """Save if the latch changed since the last save (or the last write failed); returns
        whether it wrote."""
        version, msg = self.latch.version, self.latch.state()
        if (version == self.saved and not self._failing) or msg is None:
            return False
        now = time.monotonic()
        if self._failing and version == self._tried and now < self._retry_at:
            return False  # the same state failed a moment ago: retried every RETRY s
        self._tried, self._retry_at = version, now + self.RETRY
        try:
            self.file.save(msg)
        except OSError as exc:
            self.failures += 1
            self.latch.mark_saved(version, ok=False)
            if not self._failing:
                log.error(
                    "cannot keep the e-stop latch (%s) in %s: %s - answering durable: false, "
                    "refusing releases until it can",
                    "engaged" if msg.engaged else "released",
                    self.file.path,
                    exc,
                )
            self._failing = True
            return False
        if self._failing:
            log.warning("the e-stop latch is kept again in %s", self.file.path)
        self._failing = False
        self.saved = version
        self.latch.mark_saved(version, ok=True)
        return True
