"""The one-controller rule's pure parts: how controller ids order, and what a claim does when
another controller's token comes and goes."""

from __future__ import annotations

import threading

from controller.runtime.claim import Claim, make_ident, newer, stamp_of, wait_until_alone


def test_ids_order_by_start_stamp_and_a_newcomer_is_newer_than_what_it_found():
    a = make_ident(1_000, [], pid=7, host="lab-pc.local")
    assert a == "main-1000-7-lab-pc.local" and stamp_of(a) == 1000
    assert stamp_of("main") == 0 and newer(a, "main")  # an id from before: the oldest
    # the newcomer's clock is behind: it still takes a newer stamp than the running one
    b = make_ident(900, [a], pid=8, host="other/host*")
    assert stamp_of(b) == 1001 and newer(b, a) and not newer(a, b)
    assert "/" not in b and "*" not in b  # a valid key chunk
    # same millisecond: the text decides, the same way on both sides
    c, d = "main-5-1-x", "main-5-2-x"
    assert newer(d, c) != newer(c, d)


def test_a_claim_yields_to_a_newer_controller_and_waits_out_older_ones():
    me = "main-2000-1-h"
    claim = Claim(me, found=["main-1000-9-h", me])
    assert claim.predecessors == {"main-1000-9-h"} and not claim.alone()
    claim.on_alive(me, True)  # its own token
    claim.on_alive("main-1500-3-h", True)  # another older one appears: waited out too
    assert not claim.yielded.is_set() and claim.predecessors == {"main-1000-9-h", "main-1500-3-h"}
    claim.on_alive("main-1000-9-h", False)
    claim.on_alive("main-1500-3-h", False)
    assert claim.alone() and wait_until_alone(claim, 1.0, threading.Event())
    claim.on_alive("main-3000-2-h", True)
    assert claim.yielded.is_set() and claim.yielded_to == "main-3000-2-h"
    claim.on_alive("main-4000-2-h", True)
    assert claim.yielded_to == "main-3000-2-h"  # the first one named


def test_a_take_over_gives_up_when_the_old_controller_never_goes():
    claim = Claim("main-2000-1-h", found=["main"])
    stop = threading.Event()
    assert not wait_until_alone(claim, 0.1, stop)
    stop.set()
    assert not wait_until_alone(claim, 10.0, stop)


def test_a_token_stamped_far_ahead_of_the_clock_is_no_take_over():
    """One forged token (or a clock far off) cannot make the running controller yield; a real
    take-over's stamp (its clock within a minute, or one above this one's own stamp) can."""
    now = 1_000_000.0
    claim = Claim("main-999000-1-h", found=[], clock_ms=lambda: now)
    claim.on_alive("main-99999999-6-evil", True)  # a day ahead of this test's clock
    assert not claim.yielded.is_set() and claim.implausible == {"main-99999999-6-evil"}
    assert claim.alone()  # nor a predecessor to wait for
    claim.on_alive(f"main-{int(now) + 30_000}-2-h", True)  # a host 30 s ahead: believed
    assert claim.yielded.is_set() and claim.yielded_to == f"main-{int(now) + 30_000}-2-h"
    # a controller whose own clock ran far ahead is still taken over one above its stamp
    ahead = Claim("main-5000000-1-h", found=[], clock_ms=lambda: now)
    ahead.on_alive("main-5000001-2-h", True)
    assert ahead.yielded.is_set()
