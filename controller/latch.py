"""The latched e-stop: one pure state machine held by every party (hub, controller, agents).

Imported by the controller's runtime and by ``drivers/agent.py`` (the one module of
``controller/`` besides ``controller.wire`` the robot side may import; it imports only the wire
contract and the standard library: no I/O, no clock - ``tests/unit/test_boundaries.py``).

The state is an ``EStop``: ``engaged``, ``source`` (who set it: an operator's identity) and
``epoch``, a counter only operators' actions advance (never the sender's clock ``t``, which is
kept for the log only). A holder that has learnt nothing yet is *unknown*: it holds the robots
stopped ("fail closed") and answers no latch query. The rules:

- an **operator's** message (put on ``fleet/<fleet>/estop``: under the lab ACL only operator
  identities and the controller may put there) is obeyed when it engages, whatever its epoch
  (the epoch is raised to it); a release is obeyed only when its epoch is greater than the
  latch's (an old release replayed, or re-put by a stale tool, is refused while engaged, and
  is a no-op while released: ``fleet resume`` repeats its release until every agent has it,
  stamped anew each time); in the lab a release is also refused unless stamped within
  ``fleet.max_clock_skew`` of the receiver's clock (a release recorded and replayed later, to
  holders that lost their files and so their epoch, releases nobody: ``stale_releases``);
- another **holder's answer** to a latch query (``estop/state/<role>/<id>``) can only engage:
  an engaged answer at the latch's epoch or above engages it. A released answer never releases
  a latch. The one exception is a fresh holder: an *unknown* latch adopts the newest answer of
  a ``hub`` or ``controller`` holder (under the lab ACL only the controller's identity may
  answer on those keys), never a robot's: a robot may stop the fleet, never release it;
- a **robot's** engaged answer (any role but ``hub``/``controller``) is believed only at an epoch
  no greater than ``operator_epoch + 1``: the greatest epoch this holder has seen an operator
  set (an operator's message, a trusted holder's *release* - only operators release -, its own
  file). One robot's credentials answering "engaged at 2^63-1" would otherwise lift every latch
  to an epoch no release can exceed (the fleet stopped for good); it is refused and counted
  (``implausible_epochs``). An engaged robot answer never raises an engaged latch's epoch past
  that bound, so a robot cannot ratchet it either;
- a fresh (unknown) latch takes the **most restrictive** state it sees: engaged if any usable
  answer is engaged at or above the newest trusted release's epoch (a robot's epoch clamped to
  the trusted holders' greatest + 1, or without them to the least robot epoch + 1), else the
  newest trusted release;
- a holder that keeps its latch in a file (``keeps``) answers ``durable: false`` while the held
  state is not in its file (``saved``: a write failed or is still to come) and **refuses an
  operator's release while a write has failed** (``not_durable``): robots stay held until the
  state can be kept again.

Thread-safe: zenoh's callbacks and query responders call it from their own threads.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Iterable
from dataclasses import dataclass

from controller import wire

log = logging.getLogger(__name__)

# the holders whose answers a fresh (unknown) latch may adopt, released too
TRUSTED_ROLES = ("hub", "controller")


@dataclass
class LatchCounters:
    """Refusals, for ``fleet status`` and the logs."""

    replays_refused: int = 0  # operator releases at or below the latch's epoch
    answers_refused: int = 0  # holders' released answers that would have released the latch
    stale_answers: int = 0  # engaged answers below the latch's epoch
    implausible_epochs: int = 0  # robots' engaged answers above operator_epoch + 1
    releases_refused_not_durable: int = 0  # operator releases refused: the latch is not kept
    stale_releases: int = 0  # operator releases stamped too far from the receiver's clock


@dataclass(frozen=True)
class Change:
    """What a message did to the latch: ``before``/``after`` are "engaged", "released" or
    "unknown"; ``how`` says why ("operator", "answer", "adopted", "refused: ...")."""

    before: str
    after: str
    how: str
    msg: wire.EStop

    @property
    def changed(self) -> bool:
        return self.before != self.after


class Latch:
    """One holder's latched e-stop (see the module doc). ``initial`` None: unknown (stopped)."""

    def __init__(self, holder: str, initial: wire.EStop | None = None) -> None:
        self.holder = holder  # e.g. "hub/main", "robot/r1" (for the logs)
        self._lock = threading.Lock()
        self._msg = initial
        self.counters = LatchCounters()
        self.version = 0  # bumped on every change of the held message (persistence polls it)
        # the greatest epoch an operator is known to have set (bounds robots' engaged answers)
        self.operator_epoch = 0 if initial is None else initial.epoch
        # persistence, set by the holder's keeper (``runtime.estop.LatchKeeper``): whether this
        # holder keeps a file, the version last written, whether the last write failed
        self.keeps = False
        self.saved_version = 0
        self.save_failing = False

    # -- reading
    def state(self) -> wire.EStop | None:
        """The held message (None while unknown): what this holder answers a latch query."""
        with self._lock:
            return self._msg

    def answer(self) -> wire.EStop | None:
        """What this holder answers a latch query: the held message, ``durable`` false when it
        keeps a file and the held state is not in it (None while unknown)."""
        with self._lock:
            msg = self._msg
            if msg is None or not self.keeps:
                return msg
            durable = not self.save_failing and self.saved_version == self.version
            return msg if durable else dataclasses.replace(msg, durable=False)

    @property
    def durable(self) -> bool:
        """Whether the held state is kept (always, for a holder without a file)."""
        with self._lock:
            if not self.keeps:
                return True
            return not self.save_failing and self.saved_version == self.version

    def mark_saved(self, version: int, ok: bool) -> None:
        """The keeper wrote ``version`` (``ok``) or failed to."""
        with self._lock:
            self.keeps = True
            self.save_failing = not ok
            if ok:
                self.saved_version = version

    @property
    def known(self) -> bool:
        with self._lock:
            return self._msg is not None

    @property
    def engaged(self) -> bool:
        """Whether an e-stop is latched (False while unknown: see ``stopped``)."""
        with self._lock:
            return self._msg is not None and self._msg.engaged

    @property
    def stopped(self) -> bool:
        """Whether the robots must be held stopped: engaged, or unknown (fail closed)."""
        with self._lock:
            return self._msg is None or self._msg.engaged

    @property
    def epoch(self) -> int:
        with self._lock:
            return 0 if self._msg is None else self._msg.epoch

    # -- transitions
    def operator(
        self, msg: wire.EStop, now: float | None = None, max_age: float = math.inf
    ) -> Change:
        """An operator's message (live on ``fleet/<fleet>/estop``): an engage always latches
        (epoch raised to the message's); a release only with a greater epoch, and (``now``
        given: the receiver's clock, on the lab's wall clock) only stamped within ``max_age``
        s of ``now``: an old release replayed to holders that lost their latch files (whose
        epoch it would exceed) releases nobody."""
        with self._lock:
            before = _word(self._msg)
            held = self._msg
            msg = dataclasses.replace(msg, durable=True)  # not a holder's answer
            if not msg.engaged and now is not None and not abs(now - msg.t) <= max_age:
                self.counters.stale_releases += 1
                return Change(before, before, "refused: release stamped too far from now", msg)
            if msg.engaged:
                epoch = max(msg.epoch, 0 if held is None else held.epoch)
                self._set(dataclasses.replace(msg, epoch=epoch))
                self.operator_epoch = max(self.operator_epoch, epoch)
                return Change(before, "engaged", "operator", msg)
            if held is not None and msg.epoch <= held.epoch:
                if not held.engaged:  # already released (a repeat of its own release): no-op
                    return Change(before, before, "already released", msg)
                self.counters.replays_refused += 1
                return Change(before, before, "refused: release at an old epoch", msg)
            if self.keeps and self.save_failing:
                self.counters.releases_refused_not_durable += 1
                return Change(before, before, "refused: latch not durable", msg)
            self._set(msg)
            self.operator_epoch = max(self.operator_epoch, msg.epoch)
            return Change(before, "released", "operator", msg)

    def answers(self, replies: Iterable[tuple[str, wire.EStop]]) -> Change | None:
        """Other holders' answers to a latch query, as (holder role, message): see the module
        doc. Returns the change made (None when no answer was of use)."""
        with self._lock:
            if self._msg is None:
                return self._adopt(list(replies))
            return self._engage_from(list(replies))

    def _adopt(self, replies: list[tuple[str, wire.EStop]]) -> Change | None:
        """The most restrictive state the answers show (see the module doc)."""
        if not replies:
            return None
        trusted = [m for role, m in replies if role in TRUSTED_ROLES]
        ref = max(m.epoch for m in trusted) if trusted else min(m.epoch for _, m in replies)
        released_at = max((m.epoch for m in trusted if not m.engaged), default=-1)
        engaged: list[wire.EStop] = []
        for role, m in replies:
            if not m.engaged:
                continue
            if role not in TRUSTED_ROLES and m.epoch > ref + 1:
                self.counters.implausible_epochs += 1
                m = dataclasses.replace(m, epoch=ref + 1)
            if m.epoch >= released_at:
                engaged.append(m)
            else:
                self.counters.stale_answers += 1
        self.counters.answers_refused += sum(
            1 for role, m in replies if not m.engaged and role not in TRUSTED_ROLES
        )
        if engaged:
            best = max(engaged, key=lambda m: m.epoch)
        elif released_at >= 0:
            best = max((m for m in trusted if not m.engaged), key=lambda m: m.epoch)
        else:
            return None
        best = dataclasses.replace(best, durable=True)
        self._set(best)
        self.operator_epoch = max(self.operator_epoch, best.epoch)
        return Change("unknown", _word(best), "adopted", best)

    def _engage_from(self, replies: list[tuple[str, wire.EStop]]) -> Change | None:
        held = self._msg
        if held is None:
            return None
        for role, m in replies:  # a trusted holder's release is an operator's epoch
            if role in TRUSTED_ROLES and not m.engaged:
                self.operator_epoch = max(self.operator_epoch, m.epoch)
        best: wire.EStop | None = None
        for role, m in replies:
            if not m.engaged:
                if held.engaged:
                    self.counters.answers_refused += 1
                continue
            if role not in TRUSTED_ROLES and m.epoch > self.operator_epoch + 1:
                self.counters.implausible_epochs += 1
            elif m.epoch < held.epoch:
                self.counters.stale_answers += 1
            elif (not held.engaged or m.epoch > held.epoch) and (
                best is None or m.epoch > best.epoch
            ):
                best = m
        if best is None:
            return None
        before = _word(held)
        self._set(dataclasses.replace(best, epoch=max(best.epoch, held.epoch), durable=True))
        return Change(before, "engaged", "answer", best)

    def _set(self, msg: wire.EStop) -> None:
        if msg != self._msg:
            self._msg = msg
            self.version += 1


def _word(msg: wire.EStop | None) -> str:
    if msg is None:
        return "unknown"
    return "engaged" if msg.engaged else "released"


def released_at_start(source: str, t: float = 0.0) -> wire.EStop:
    """The explicit release a fresh world starts with (the dry run: no operator, no history):
    epoch 0, so any operator's engage outranks it and any operator's release is newer."""
    return wire.EStop(t=t, engaged=False, source=source, reason="fresh world", epoch=0)


# what in-process parties (the dry run's node and agents, replay, tests) start with by default;
# the lab's processes start from the latch's file or unknown
FRESH_WORLD = released_at_start("fresh world")


def note_latch(holder: str, change: Change | None) -> None:
    """Log a change of ``holder``'s latch, or a refusal, once, with who caused it."""
    if change is None:
        return
    m = change.msg
    if change.how.startswith("refused"):
        word = "engage" if m.engaged else "release"
        how = change.how
        log.warning("%s: e-stop %s by %s (epoch %d) %s", holder, word, m.source, m.epoch, how)
    elif change.changed:
        how = change.how
        # an engaged e-stop is worth a warning wherever it shows; a release is an operator's
        # ordinary act (info)
        level = logging.WARNING if m.engaged else logging.INFO
        log.log(
            level,
            "%s: e-stop %s by %s (message epoch %d, %s)",
            holder,
            change.after,
            m.source,
            m.epoch,
            how,
        )


def role_of(key: str, fleet: str) -> str:
    """The holder role named by a latch key (``estop/state/<role>/<id>``), "" if not one."""
    parsed = wire.parse_key(key, fleet)
    if parsed is None or parsed.topic.name != "estop_state":
        return ""
    return parsed.parts.get("role", "")
