"""The e-stop latch (``controller.latch``): a table of transitions, from each starting state
(unknown, released, engaged) and each kind of input (an operator's message, a holder's answer),
and the latch's file (``runtime.estop.LatchFile``)."""

from __future__ import annotations

import threading

import pytest

from controller import wire
from controller.config import LogSection
from controller.latch import Latch
from controller.runtime.estop import LatchFile, LatchKeeper
from tests.support.config import make_config

FUTURE = 1.0e9  # a sender's clock far ahead: it must order nothing


def op(engaged: bool, epoch: int, t: float = 1.0) -> wire.EStop:
    return wire.EStop(t=t, engaged=engaged, source="alice@lab", epoch=epoch)


def start(state: str) -> Latch:
    initial = {"unknown": None, "released": op(False, 5), "engaged": op(True, 5)}[state]
    return Latch("test", initial)


def word(latch: Latch) -> str:
    held = latch.state()
    return "unknown" if held is None else ("engaged" if held.engaged else "released")


# (start, operator message (engaged, epoch), state after, epoch after)
OPERATOR = [
    ("unknown", (True, 0), "engaged", 0),
    ("unknown", (False, 1), "released", 1),
    ("released", (True, 1), "engaged", 5),  # an engage always latches; the epoch never drops
    ("released", (True, 6), "engaged", 6),
    ("engaged", (False, 6), "released", 6),
    ("engaged", (False, 5), "engaged", 5),  # a replayed release (same epoch): refused
    ("engaged", (False, 4), "engaged", 5),  # an older one: refused
    ("engaged", (True, 9), "engaged", 9),
    ("released", (False, 5), "released", 5),  # a repeat: no-op, not a refusal
    ("released", (False, 3), "released", 5),
]


@pytest.mark.parametrize(("first", "msg", "after", "epoch"), OPERATOR)
def test_operator_messages(first, msg, after, epoch):
    latch = start(first)
    change = latch.operator(op(*msg, t=FUTURE))
    assert (word(latch), latch.epoch) == (after, epoch)
    assert latch.stopped == (after != "released")
    refused = first == "engaged" and not msg[0] and msg[1] <= 5
    assert change.how.startswith("refused") == refused
    assert latch.counters.replays_refused == int(refused)


# (start, [(answering role, engaged, epoch)], state after, epoch after)
ANSWERS = [
    # a fresh latch adopts the hub's or the controller's answer, released too, never a robot's
    ("unknown", [("hub", False, 7)], "released", 7),
    ("unknown", [("controller", False, 7)], "released", 7),
    ("unknown", [("robot", False, 7)], "unknown", 0),
    ("unknown", [("robot", True, 0)], "engaged", 0),
    # the newest epoch wins among what it may adopt; a stale engage loses to a newer release
    ("unknown", [("robot", True, 6), ("hub", False, 7)], "released", 7),
    ("unknown", [("hub", False, 7), ("robot", True, 7)], "engaged", 7),
    ("unknown", [("hub", False, 7), ("robot", False, 9)], "released", 7),
    # a known latch: an answer can only engage, at its epoch or above
    ("released", [("hub", False, 9)], "released", 5),
    ("released", [("robot", True, 5)], "engaged", 5),
    ("released", [("robot", True, 4)], "released", 5),  # stale: an operator released since
    ("engaged", [("hub", False, 9)], "engaged", 5),
    ("engaged", [("robot", False, 6)], "engaged", 5),
    ("engaged", [("robot", True, 8)], "engaged", 8),
]


@pytest.mark.parametrize(("first", "answers", "after", "epoch"), ANSWERS)
def test_answers(first, answers, after, epoch):
    latch = start(first)
    latch.answers([(role, op(engaged, e, t=FUTURE)) for role, engaged, e in answers])
    assert (word(latch), latch.epoch) == (after, epoch)


def test_the_attack_a_robots_future_released_answer_then_a_replayed_release():
    latch = Latch("hub/main", op(False, 3))
    latch.operator(op(True, 4))  # the operator stops the fleet
    change = latch.answers([("robot", wire.EStop(t=FUTURE, engaged=False, source="robot/r1"))])
    assert change is None and latch.stopped and latch.counters.answers_refused == 1
    change = latch.operator(op(False, 3, t=FUTURE))  # the old resume, put again
    assert change.how.startswith("refused") and latch.stopped
    assert latch.counters.replays_refused == 1
    latch.operator(op(False, 5))  # the operator's new resume
    assert not latch.stopped and latch.state().source == "alice@lab"


def test_a_robot_may_stop_the_fleet():
    latch = Latch("hub/main", op(False, 3))
    change = latch.answers([("robot", wire.EStop(t=0.0, engaged=True, epoch=3, source="r1"))])
    assert change is not None and change.changed and latch.stopped


def test_thread_safe_under_concurrent_engages_and_releases():
    latch = Latch("t", op(False, 0))

    def operators(first: int) -> None:
        for e in range(first, 2000, 2):
            latch.operator(op(e % 4 == 0, e))

    threads = [threading.Thread(target=operators, args=(k,)) for k in (0, 1)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert latch.epoch >= 1998 and latch.version > 0


def test_the_latch_file_round_trips_and_a_corrupt_file_is_unknown(tmp_path):
    cfg = make_config({"log": {"dir": str(tmp_path / "runs")}})
    file = LatchFile(cfg, "hub")
    assert file.path == tmp_path / "runs" / "estop-lab-hub.json"
    assert file.load() is None  # no file: unknown
    latch = Latch("hub/main", None)
    keeper = LatchKeeper(latch, file)
    assert not keeper.poll()  # nothing to keep while unknown
    latch.operator(op(True, 2))
    assert keeper.poll() and not keeper.poll()  # written once per change
    assert file.load() == latch.state()
    assert not list(file.path.parent.glob("*.tmp"))
    file.path.write_bytes(b'{"t": 1.0, "engaged": tru')  # a torn write by another tool
    assert file.load() is None


def test_state_dir_overrides_the_log_dir(tmp_path):
    cfg = make_config({"log": {"dir": str(tmp_path / "runs"), "state_dir": str(tmp_path / "s")}})
    assert LatchFile(cfg, "controller").path == tmp_path / "s" / "estop-lab-controller.json"
    assert LogSection().state_dir == ""
