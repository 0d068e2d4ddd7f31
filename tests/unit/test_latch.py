"""The e-stop latch (``controller.latch``): a table of transitions, from each starting state
(unknown, released, engaged) and each kind of input (an operator's message, a holder's answer),
and the latch's file (``runtime.estop.LatchFile``)."""

from __future__ import annotations

import threading

import pytest

from controller import wire
from controller.config import LogSection, load_config
from controller.latch import Latch
from controller.runtime.estop import LatchFile, LatchKeeper
from tests.support.config import base_config_dict, make_config, write_toml

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
    ("engaged", [("robot", True, 6)], "engaged", 6),
    # issue 31: a robot's engage is believed up to the operator's epoch + 1, no further
    ("engaged", [("robot", True, 8)], "engaged", 5),
    ("released", [("robot", True, 7)], "released", 5),
    ("released", [("robot", True, wire.MAX_SEQ)], "released", 5),
    ("released", [("hub", True, 9)], "engaged", 9),  # the hub and controller are trusted
    # a fresh latch takes the most restrictive state it sees (a robot's epoch clamped)
    ("unknown", [("hub", False, 7), ("robot", True, wire.MAX_SEQ)], "engaged", 8),
    ("unknown", [("robot", False, 3), ("robot", True, wire.MAX_SEQ)], "engaged", 4),
    ("unknown", [("hub", False, 7), ("controller", True, 7)], "engaged", 7),
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


def test_an_old_release_replayed_to_a_fresh_holder_releases_nothing():
    """Holders that lost their files start unknown (epoch 0): a release recorded an hour ago
    (epoch 7, above theirs) is refused on the lab's clock and counted; the operator's fresh
    release is obeyed; an engage is never refused for its stamp."""
    now = 10_000.0
    latch = start("unknown")
    change = latch.operator(op(False, 7, t=now - 3600.0), now, 1.0)
    assert word(latch) == "unknown" and not change.changed and "stamped" in change.how
    assert latch.counters.stale_releases == 1
    latch.operator(op(False, 7, t=now - 3600.0))  # the dry run (no clock check): obeyed
    assert word(latch) == "released"
    latch = start("unknown")
    assert latch.operator(op(False, 1, t=now + 5.0), now, 1.0).after == "unknown"  # ahead too
    assert latch.operator(op(False, 1, t=now - 0.4), now, 1.0).after == "released"
    assert latch.operator(op(True, 2, t=now - 3600.0), now, 1.0).after == "engaged"


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


def test_a_robots_engage_at_max_seq_cannot_lock_the_fleet_stopped():
    """Issue 31 item 2: one robot's credentials answer "engaged at 2^63-1"."""
    forged = wire.EStop(t=0.0, engaged=True, source="r1", epoch=wire.MAX_SEQ)
    for first in ("released", "engaged"):
        latch = start(first)
        latch.answers([("robot", forged)])
        assert latch.epoch == 5 and latch.counters.implausible_epochs == 1
        latch.operator(op(False, 6))  # the operator's next resume
        assert not latch.stopped and latch.epoch == 6
    fresh = Latch("robot/r2", None)  # a fresh agent that hears only robots
    fresh.answers([("robot", op(False, 5)), ("robot", forged)])
    assert fresh.stopped and fresh.epoch == 6  # stopped, at an epoch a release can exceed
    fresh.operator(op(False, 7))
    assert not fresh.stopped
    # a robot's honest engage right after the operator's epoch still stops the fleet, once
    latch = start("released")
    latch.answers([("robot", op(True, 6))])
    assert latch.stopped and latch.epoch == 6
    latch.answers([("robot", op(True, 7))])  # no ratchet above operator + 1
    assert latch.epoch == 6


def test_a_holder_that_cannot_keep_its_latch_says_so_and_refuses_releases(tmp_path):
    cfg = make_config({"fleet": {"state_dir": str(tmp_path / "state")}})
    file = LatchFile(cfg, "hub")
    latch = Latch("hub/main", op(False, 5))
    keeper = LatchKeeper(latch, file)
    assert file.load() == op(False, 5) and latch.answer().durable  # kept at start
    file.path.unlink()
    file.path.mkdir()  # the latch's path is a folder: every write fails (root too)
    latch.operator(op(True, 0))
    assert latch.answer().durable is False  # before the keeper's write: not yet kept
    assert not keeper.poll()
    assert latch.answer().durable is False and latch.answer().engaged
    assert b"durable" in wire.encode(latch.answer())  # on the wire only when false
    assert b"durable" not in wire.encode(op(True, 5))
    change = latch.operator(op(False, 6))
    assert change.how.startswith("refused") and latch.stopped
    assert latch.counters.releases_refused_not_durable == 1
    file.path.rmdir()  # the folder is writable again
    keeper._retry_at = 0.0  # (retries are throttled to every RETRY s)
    assert keeper.poll() and latch.answer().durable and file.load().engaged
    latch.operator(op(False, 6))
    assert not latch.stopped


def test_a_holder_starting_where_it_cannot_write_starts_engaged_not_durable(tmp_path):
    cfg = make_config({"fleet": {"state_dir": str(tmp_path / "state")}})
    file = LatchFile(cfg, "hub")
    file.save(op(False, 5))  # a release kept; an engage since failed to reach the file
    (file.path.parent / (file.path.name + ".tmp")).mkdir()  # every write fails (root too)
    latch = Latch("hub/main", file.load_kept("hub/main"))
    keeper = LatchKeeper(latch, file)
    assert latch.stopped and latch.epoch == 5 and latch.answer().durable is False
    assert latch.operator(op(False, 6)).how.startswith("refused") and latch.stopped
    (file.path.parent / (file.path.name + ".tmp")).rmdir()
    keeper._retry_at = 0.0
    assert keeper.poll() and latch.answer().durable and file.load().engaged
    # a missing file in a folder that cannot be written: engaged too (not unknown), not durable
    file.path.unlink()
    (file.path.parent / (file.path.name + ".tmp")).mkdir()
    latch = Latch("hub/main", file.load_kept("hub/main"))
    LatchKeeper(latch, file)
    assert latch.stopped and latch.answer() is not None and latch.answer().durable is False


def test_the_release_epoch_ignores_an_impostors_max_seq():
    from controller.runtime.estop import EPOCH_SLACK, release_epoch

    def h(epoch, engaged=True):
        return {"engaged": engaged, "epoch": epoch, "source": "x", "durable": True}

    states = [("hub/main", h(5)), ("robot/r1", h(wire.MAX_SEQ)), ("robot/r2", h(7))]
    assert release_epoch(states) == (8, 5 + EPOCH_SLACK)
    assert release_epoch([("robot/r1", h(wire.MAX_SEQ)), ("robot/r2", h(3))])[0] == 4
    assert release_epoch([])[0] == 1


def test_the_state_folder_is_not_the_log_folder(tmp_path):
    runs = str(tmp_path / "runs")
    cfg = make_config({"log": {"dir": runs}})
    assert LatchFile(cfg, "hub").path == tmp_path / "state" / "estop-lab-hub.json"
    cfg = make_config({"log": {"dir": runs}, "fleet": {"state_dir": str(tmp_path / "s")}})
    assert LatchFile(cfg, "hub").path == tmp_path / "s" / "estop-lab-hub.json"
    # beside the config file (relative paths too)
    (tmp_path / "etc").mkdir()
    conf = write_toml(tmp_path / "etc" / "lab.toml", base_config_dict() | {"log": {"dir": runs}})
    cfg = load_config(conf)
    assert LatchFile(cfg, "hub").path == tmp_path / "etc" / "state" / "estop-lab-hub.json"
    data = base_config_dict()
    data["fleet"]["state_dir"] = "keep"
    cfg = load_config(write_toml(tmp_path / "etc" / "b.toml", data))
    assert LatchFile(cfg, "hub").path == tmp_path / "etc" / "keep" / "estop-lab-hub.json"


def test_a_latch_in_the_old_place_is_read_and_moved(tmp_path):
    cfg = make_config({"log": {"dir": str(tmp_path / "runs")}})
    old = tmp_path / "runs" / "estop-lab-hub.json"
    old.parent.mkdir()
    old.write_bytes(wire.encode(op(True, 4)))
    file = LatchFile(cfg, "hub")
    latch = Latch("hub/main", file.load_kept("hub/main"))
    assert latch.stopped and latch.epoch == 4
    LatchKeeper(latch, file)
    assert wire.decode(wire.EStop, file.path.read_bytes()) == op(True, 4)


def test_the_latch_file_round_trips_and_a_corrupt_file_is_unknown(tmp_path):
    cfg = make_config({"log": {"dir": str(tmp_path / "runs")}})
    file = LatchFile(cfg, "hub")
    assert file.path == tmp_path / "state" / "estop-lab-hub.json"
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
    # the older key still works (fleet.state_dir is preferred)
    cfg = make_config({"log": {"dir": str(tmp_path / "runs"), "state_dir": str(tmp_path / "s")}})
    assert LatchFile(cfg, "controller").path == tmp_path / "s" / "estop-lab-controller.json"
    assert LogSection().state_dir == ""


def test_an_unconfirmed_resume_names_what_to_check():
    """A resume some agent did not confirm says what to check: the agent up, the clocks (a
    release stamped beyond fleet.max_clock_skew of a holder's clock is refused as a replay)."""
    from controller.runtime.estop import describe_put

    result = {"agents_missing": ["r2"], "agents_confirmed": ["r1"], "durable": True}
    text = describe_put("resume", result)
    assert text.startswith("fleet resume: sent; NOT confirmed by r2 (confirmed by r1)")
    assert "fleet status" in text and "max_clock_skew" in text and "NTP" in text
    assert "clock" not in describe_put("estop", result)  # an engage is never refused so
