"""The daemon recorder's tap over the hub's path and the e-stop's second path: an e-stop that
comes by both is logged once, one that comes by the second path alone is logged, a repeat on
one path is logged as it comes, other keys pass through."""

from __future__ import annotations

from controller.runtime.recording import TwoPathTap

KEY = "fleet/lab/estop"


def test_an_estop_by_both_paths_is_logged_once_and_one_by_the_second_alone_is_logged():
    logged: list[tuple[str, bytes]] = []
    tap = TwoPathTap(lambda k, p, t: logged.append((k, p)), KEY)
    hub, second = tap.path("hub"), tap.path("second")
    hub(KEY, b"stop-1", 1.0)
    second(KEY, b"stop-1", 1.01)  # the same put, by the other path: not again
    second(KEY, b"stop-2", 2.0)  # the hub hung: only the second path brought it
    hub(KEY, b"stop-2", 9.0)  # the hub back, late: not again
    second(KEY, b"stop-2", 2.5)  # the tool's repeat on the same path: logged as it came
    hub("fleet/lab/robot/r1/state", b"s", 3.0)
    hub("fleet/lab/robot/r1/state", b"s", 3.1)  # other keys: every sample
    assert logged == [
        (KEY, b"stop-1"),
        (KEY, b"stop-2"),
        (KEY, b"stop-2"),
        ("fleet/lab/robot/r1/state", b"s"),
        ("fleet/lab/robot/r1/state", b"s"),
    ]


def test_the_tap_remembers_a_bounded_number_of_estops():
    tap = TwoPathTap(lambda k, p, t: None, KEY)
    for i in range(3 * TwoPathTap.KEEP):
        tap.path("hub")(KEY, str(i).encode(), float(i))
    assert len(tap._seen) == TwoPathTap.KEEP
