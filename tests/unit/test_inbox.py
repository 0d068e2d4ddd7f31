"""The bus's inbox and decoder: bounded per key (a flood evicts only its own oldest samples),
raw bytes decoded on the decoder thread, never on the producer's (zenoh's) thread, bad ones
never reaching an inbox."""

from __future__ import annotations

import threading

from controller import wire
from controller.io.bus import Decoder, DecodeStats, Inbox, KeyRate, Received, _Raw, decode_payload

FLEET = "lab"


def _pose(i: int) -> wire.PoseMeasurement:
    return wire.PoseMeasurement(t=float(i), seq=i, x=0.1 * i, y=0.0, theta=0.0)


def _key(rid: str) -> str:
    return wire.key("robot_pose", FLEET, id=rid)


def test_a_flooding_key_evicts_only_its_own_oldest_samples():
    dropped: list[str] = []
    box = Inbox(depth=4, on_drop=dropped.append)
    box.put(Received(0.0, _key("r2"), _pose(1000)))
    for i in range(100):  # r1 floods
        box.put(Received(0.0, _key("r1"), _pose(i)))
    box.put(Received(0.0, _key("r2"), _pose(1001)))
    assert box.qsize() == 4 + 2
    assert box.overflow == 96 and dropped == [_key("r1")] * 96
    got = box.drain()
    assert [r.msg.seq for r in got] == [1000, 96, 97, 98, 99, 1001]  # newest kept, in order
    assert box.qsize() == 0 and box.drain() == []


def test_get_returns_the_oldest_across_keys():
    box = Inbox(depth=8)
    box.put(Received(0.0, _key("r2"), _pose(5)))
    box.put(Received(0.0, _key("r1"), _pose(6)))
    assert box.get(timeout=0.5).msg.seq == 5
    assert box.get(timeout=0.5).msg.seq == 6
    assert box.get(timeout=0.01) is None


def test_a_total_bound_drops_the_newcomer():
    box = Inbox(maxsize=1)
    a = Received(0.0, "k", wire.EStop(t=1.0, engaged=True))
    box.put(a)
    box.put(Received(0.0, "k", wire.EStop(t=2.0, engaged=False)))
    assert box.overflow == 1 and box.drain() == [a]


def test_the_decoder_thread_decodes_off_the_producers_thread_and_drops_garbage():
    stats = DecodeStats()
    threads: list[str] = []
    seen: list[int] = []

    def decode(key: str, payload: bytes):
        threads.append(threading.current_thread().name)
        return decode_payload(FLEET, key, payload, wire.PoseMeasurement, stats)

    box = Inbox(depth=8)
    dec = Decoder(depth=8, on_drop=stats.overflowed)
    try:
        for p in (wire.encode(_pose(1)), b"junk", wire.encode(_pose(2))):
            dec.submit(
                _Raw(3.0, _key("r1"), p, decode, box, lambda r: seen.append(r.msg.seq)), False
            )
        got = [box.get(timeout=5.0), box.get(timeout=5.0)]
    finally:
        dec.close()
    assert [r.msg.seq for r in got] == [1, 2] and got[0].recv_time == 3.0
    assert seen == [1, 2]  # on_message after enqueueing
    assert set(threads) == {"bus-decoder"}
    assert stats.counts == {_key("r1"): 1} and box.qsize() == 0  # junk counted, never queued


def test_a_key_over_its_rate_is_refused_and_other_keys_are_not():
    """A key at 20x its limit gets the limit's rate (after a burst of 0.25 s' worth); another
    key at a normal rate loses nothing; a key quiet for a while gets its burst back."""
    rate = KeyRate(100.0)  # 100 Hz, bursts of 25
    flood = [rate.allow("r1", i / 2000.0) for i in range(2000)]  # 2 kHz for 1 s
    normal = [rate.allow("r2", i / 30.0) for i in range(30)]  # 30 Hz for 1 s
    assert 120 <= sum(flood) <= 126  # 25 at once, then 100 a second
    assert all(normal)
    assert sum(rate.allow("r1", 11.0 + i * 1e-4) for i in range(40)) == 25  # 10 s later
