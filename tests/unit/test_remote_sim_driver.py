"""The remote sim driver (a robot of ``fleet world``) on the in-memory bus, on a fake clock:
the connect handshake, the keepalive of the last command, a silent world as a lost link that
comes back."""

from __future__ import annotations

import pytest

from controller import wire
from drivers.base import Capabilities, ConnectTimeout, LinkLost
from drivers.remote_sim import RemoteSimDriver
from tests.support.fakebus import FakeBus

CAPS = Capabilities("omni", True, 0.5, 2.0, 0.1)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _pose(t: float) -> wire.PoseMeasurement:
    return wire.PoseMeasurement(t=t, x=1.0, y=2.0, theta=0.0, source="sim")


@pytest.fixture
def rig():
    bus, clock = FakeBus("lab"), Clock()
    drv = RemoteSimDriver(bus, "r1", CAPS, clock=clock, monotonic=clock, link_timeout=2.5)
    return bus, clock, drv


def test_connect_needs_the_worlds_first_sample(rig):
    bus, _, drv = rig
    with pytest.raises(ConnectTimeout, match="sim/world/r1/pose"):
        drv.connect(timeout=0.0)
    bus.deliver("world_pose", _pose(1.0), id="r1")
    drv.connect(timeout=0.0)
    assert [m.x for m in drv.poll()] == [1.0] and drv.poll() == []


def test_commands_carry_the_vehicle_timeout_and_are_repeated(rig):
    bus, clock, drv = rig
    bus.deliver("world_pose", _pose(1.0), id="r1")
    drv.connect(timeout=0.0)
    drv.send(wire.Twist2D(t=0.0, vx=0.2))
    key = bus.key("world_cmd", id="r1")
    assert bus.sent[key][-1].vx == 0.2 and bus.sent[key][-1].ttl == drv.vehicle_timeout
    assert bus.sent[key][-1].t == clock.t  # stamped on the lab's clock
    drv.health()
    assert len(bus.sent[key]) == 1  # not yet due
    clock.t += 0.15
    bus.deliver("world_pose", _pose(2.0), id="r1")
    assert drv.health().ok and len(bus.sent[key]) == 2 and bus.sent[key][-1].vx == 0.2
    drv.stop()
    assert bus.sent[key][-1].vx == 0.0


def test_a_silent_world_is_a_lost_link_that_comes_back(rig):
    bus, clock, drv = rig
    bus.deliver("world_pose", _pose(1.0), id="r1")
    drv.connect(timeout=0.0)
    clock.t += 3.0
    h = drv.health()
    assert not h.ok and "no pose from the world process" in h.detail
    with pytest.raises(LinkLost):
        drv.send(wire.Twist2D(t=0.0, vx=0.2))
    bus.deliver("world_pose", _pose(4.0), id="r1")
    assert drv.health().ok
    drv.close()
    drv.close()
    assert drv.poll() == []


def test_connect_timeout_names_what_it_waited_for_and_the_flag(rig):
    _, _, drv = rig
    with pytest.raises(ConnectTimeout) as info:
        drv.connect(timeout=0.0)
    msg = str(info.value)
    assert msg.startswith("no pose from the world process for robot r1 after 0 s")
    assert "is fleet world running with this robot?" in msg and "--connect-timeout" in msg
