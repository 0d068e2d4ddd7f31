"""A lab rehearsal on one machine, as separate processes on 127.0.0.1: ``fleet world`` (the
shared ideal world, real time), ``fleet daemon --mission capture`` and one ``fleet driver`` per
robot attached to the world (``sim.world = "process"``). The daemon captures the object the world
publishes on ``object/pose``; killed (SIGKILL) after the arrest, every agent stops its robot within
``cmd_ttl`` + one tick (seen in the world's truth); a restarted daemon finds the agents again, and
killed while the robots drive (staging), every agent stops its robot again."""

from __future__ import annotations

import math
import signal
import sys
import time

from controller import wire
from controller.io.bus import Bus
from controller.replay.log import events_of, load_run, phases_of
from tests.support.config import base_config_dict, write_toml
from tests.support.lab import connect_client, release, spawn, stop_all, tail
from tests.support.wait import wait_for
from tests.support.world_lab import ROBOTS, all_present, daemon_status, rehearsal_config

MOVED = 1e-4  # m or rad between two truth samples: the robot moved
SCHED = 0.2  # s of scheduling delay allowed on the shared machine (see the bounds below)


class Truth:
    """The world's ground truth of every robot, as it arrives: (t, x, y, theta) per robot."""

    def __init__(self, bus: Bus) -> None:
        self.inbox = bus.subscribe_topic("truth_robot", lossless=True)  # the whole history
        self.tracks: dict[str, list[tuple[float, float, float, float]]] = {r: [] for r in ROBOTS}

    def take(self) -> float:
        """Drain what arrived; returns the newest stamp every robot has reached (-inf if none)."""
        for item in self.inbox.drain():
            rid = wire.parse_key(item.key).id
            m = item.msg
            self.tracks.setdefault(rid, []).append((m.t, m.x, m.y, m.theta))
        return min((tr[-1][0] if tr else -math.inf) for tr in self.tracks.values())

    def last_motion(self, rid: str) -> float:
        """The stamp of the robot's last truth sample that differs from the one before."""
        tr = self.tracks[rid]
        last = -math.inf
        for a, b in zip(tr, tr[1:], strict=False):
            if max(abs(b[1] - a[1]), abs(b[2] - a[2]), abs(b[3] - a[3])) > MOVED:
                last = b[0]
        return last

    def moved_between(self, rid: str, t0: float, t1: float) -> float:
        """How far (m) the robot went between t0 and t1."""
        pts = [(x, y) for t, x, y, _ in self.tracks[rid] if t0 <= t <= t1]
        return sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))


def _arrested(inbox, seen: list[str]) -> bool:
    seen += [i.msg.data.get("phase", i.msg.phase) for i in inbox.drain()]
    return "arrested" in seen


def _kill_and_watch(daemon, truth: Truth, cmds, ttl: float, tick: float) -> dict:
    """SIGKILL the daemon and follow the world past cmd_ttl + one tick + 1 s. Returns, per
    robot: ``stop_cmd`` (s after the kill its agent put the zero command to the world),
    ``last_motion`` (s after the kill its truth last changed), ``speed`` (m/s, 0.25 s before)."""
    cmds.drain()
    t_kill = time.time()
    daemon.kill()
    daemon.wait()
    wait_for(lambda: truth.take() > t_kill + ttl + tick + 1.0, 10, "the truth after the kill")
    stop_cmd: dict[str, float] = {}
    for item in cmds.drain():
        m, rid = item.msg, wire.parse_key(item.key).id
        if rid not in stop_cmd and m.t > t_kill and m.vx == m.vy == m.wz == 0.0:
            stop_cmd[rid] = round(m.t - t_kill, 3)
    out = {
        r: {
            "stop_cmd": stop_cmd.get(r, math.inf),
            "last_motion": round(truth.last_motion(r) - t_kill, 3),
            "speed": round(truth.moved_between(r, t_kill - 0.25, t_kill) / 0.25, 3),
        }
        for r in ROBOTS
    }
    print(f"\nkill: {out}", file=sys.stderr)
    return out


def _moving(truth: Truth, n: int) -> bool:
    """At least ``n`` robots go faster than 0.1 m/s over the last 0.25 s of fresh truth."""
    t = truth.take()
    fresh = t > time.time() - 0.25
    return fresh and sum(truth.moved_between(r, t - 0.25, t) > 0.025 for r in ROBOTS) >= n


def test_world_daemon_drivers_arrest_kill_restart(tmp_path, port):
    t_start = time.monotonic()
    cfg, fleet_keys = rehearsal_config(tmp_path, port)
    c = str(cfg)
    ttl, tick = fleet_keys["cmd_ttl"], 1.0 / fleet_keys["rate_hz"]
    # the agent's watchdog: cmd_ttl + one tick after the last command it took in, which came
    # up to one tick before the kill (the daemon's last tick) and one tick after (the agent's
    # loop); plus SCHED for the scheduling of six Python processes on 2 shared cores (measured:
    # 0.29-0.38 s on a quiet machine, up to 0.58 s under a load of 8). The world's truth shows
    # the stop one loop period (50 Hz) and one truth period (rate_hz) later.
    stop_bound = ttl + 2 * tick + SCHED
    still_bound = stop_bound + 0.02 + tick
    world = spawn(tmp_path / "world.txt", "world", "--config", c)
    procs = [world]

    def daemon(n: int, mission: str):
        out = str(tmp_path / f"d{n}.mcap")
        args = ("daemon", "--config", c, "--mission", mission, "--out", out)
        p = spawn(tmp_path / f"daemon{n}.txt", *args)
        procs.append(p)
        return p

    try:
        bus = connect_client(port, "the world")
        with bus:
            truth = Truth(bus)
            phases = bus.subscribe_topic("plan", lossless=True, what="phase")
            cmds = bus.subscribe_topic("world_cmd", lossless=True)  # read as a history
            wait_for(lambda: truth.take() > 0, 20, "the world's truth")
            d1 = daemon(1, "capture")
            agents = [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ROBOTS]
            procs += agents
            # a fresh lab is stopped until an operator's first resume; the daemon must be up to
            # hear it (a holder's answer never releases a fresh daemon's latch)
            wait_for(lambda: all_present(daemon_status(cfg)), 60, "the daemon and its robots")
            release(cfg, timeout=90)
            seen: list[str] = []
            wait_for(lambda: _arrested(phases, seen), 45, "the daemon's arrest")
            assert seen[0] == "approach" and "hold" in seen, seen

            # killed after the arrest (the robots hold still): they stay stopped
            k = _kill_and_watch(d1, truth, cmds, ttl, tick)
            assert max(v["stop_cmd"] for v in k.values()) <= stop_bound, (k, stop_bound)
            assert max(v["last_motion"] for v in k.values()) <= still_bound, (k, still_bound)
            assert all(a.poll() is None for a in agents), "an agent exited"

            # restarted (staging: the robots back off to a ring around the crate), it finds
            # the agents again; killed while they drive, each agent stops its own robot
            d2 = daemon(2, "stage")
            wait_for(lambda: all_present(daemon_status(cfg)), 30, "the restarted daemon's agents")
            wait_for(lambda: _moving(truth, 1), 20, "the robots on their way")
            k = _kill_and_watch(d2, truth, cmds, ttl, tick)
            # (a daemon held up over 1 s by the machine commands zero until the e-stop latch
            # is read again: one robot still moving is enough to time the stop)
            assert any(v["speed"] > 0.05 for v in k.values()), k
            assert max(v["stop_cmd"] for v in k.values()) <= stop_bound, (k, stop_bound)
            assert max(v["last_motion"] for v in k.values()) <= still_bound, (k, still_bound)
            assert all(a.poll() is None for a in agents), "an agent exited"
    finally:
        codes = stop_all(procs)
    expected = [0, -9] + [0] * len(ROBOTS) + [-9]
    assert codes == expected, (codes, [tail(p) for p in procs])
    assert "real-time factor" in tail(world)
    print(tail(world, 400), file=sys.stderr)
    print(f"rehearsal test: {time.monotonic() - t_start:.1f} s", file=sys.stderr)


def test_a_driver_killed_mid_approach_is_lost_replanned_and_the_rest_arrest(tmp_path, port):
    """Six robots on the rehearsal world; the agent of a robot holding a capture point is
    killed (SIGKILL) during the approach: the daemon sees it gone within 0.5 s (its liveliness
    token goes with its TCP link), re-plans the capture with the five left, and they arrest."""
    cfg_path, _ = rehearsal_config(tmp_path, port)
    import tomllib

    data = tomllib.loads(cfg_path.read_text())
    six = base_config_dict()["robots"][:6]
    ring = [(3.3, 1.6, 1.57), (4.7, 3.2, 3.14), (3.3, 4.6, -1.57), (1.7, 3.2, 0.0),
            (4.6, 1.8, 2.36), (1.8, 4.5, -0.79)]  # fmt: skip
    for r, s in zip(six, ring, strict=True):
        r["start"] = list(s)
    data["robots"] = six
    c = str(write_toml(tmp_path / "six.toml", data))
    ids = [r["id"] for r in six]
    world = spawn(tmp_path / "world.txt", "world", "--config", c)
    procs = [world]
    try:
        with connect_client(port, "the world") as bus:
            plans = bus.subscribe_topic("plan", lossless=True, what="*")
            truth = Truth(bus)
            wait_for(lambda: truth.take() > 0, 20, "the world's truth")
            procs.append(spawn(tmp_path / "d.txt", "daemon", "--config", c, "--mission",
                               "capture", "--out", str(tmp_path / "d.mcap")))  # fmt: skip
            agents = {r: spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ids}
            procs += list(agents.values())
            # the daemon up before the operator's first resume (see above)
            wait_for(
                lambda: all_present(daemon_status(c), set(ids)), 60, "the daemon and its robots"
            )
            release(c, timeout=90)
            events: list = []

            def seen(kind: str) -> list:
                events.extend(plans.drain())
                return [e for e in events if wire.parse_key(e.key).parts.get("what") == kind]

            wait_for(lambda: seen("capture"), 30, "the capture plan")
            victim = seen("capture")[0].msg.data["robots"][0]
            wait_for(lambda: any(e.msg.data.get("phase") == "approach" for e in seen("phase")),
                     20, "the approach")  # fmt: skip
            t_kill = time.time()
            agents[victim].kill()
            wait_for(lambda: seen("robot_lost"), 5, "the lost robot reported")
            lost = seen("robot_lost")[0]
            assert lost.msg.data["robot"] == victim
            assert lost.recv_time - t_kill <= 0.5, lost.recv_time - t_kill
            wait_for(lambda: len(seen("capture")) >= 2, 5, "the re-planned capture")
            replanned = seen("capture")[-1].msg.data
            assert victim not in replanned["robots"], replanned
            wait_for(lambda: any(e.msg.data.get("phase") == "arrested" for e in seen("phase")),
                     60, "the arrest by the robots left")  # fmt: skip
            print(f"\nlost after {lost.recv_time - t_kill:.3f} s; re-planned with "
                  f"{replanned['robots']}", file=sys.stderr)  # fmt: skip
    finally:
        stop_all(procs)


def test_a_stalled_world_is_one_outage_not_six_losses_and_the_job_goes_on(tmp_path, port):
    """The shared world (the lab's only source of poses, and the bus endpoint every process
    joins) stops for 1.5 s mid-approach (SIGSTOP): every robot goes quiet at once. The daemon
    counts one outage, pauses (every robot commanded still) within ``fleet.outage_grace`` (3 s),
    loses nobody, and the robots arrest the object once the world runs again."""
    cfg_path, _ = rehearsal_config(tmp_path, port)
    c = str(cfg_path)
    world = spawn(tmp_path / "world.txt", "world", "--config", c)
    procs = [world]
    out = tmp_path / "d.mcap"
    try:
        with connect_client(port, "the world") as bus:
            plans = bus.subscribe_topic("plan", lossless=True, what="phase")
            truth = Truth(bus)
            wait_for(lambda: truth.take() > 0, 20, "the world's truth")
            procs.append(spawn(tmp_path / "d.txt", "daemon", "--config", c, "--mission",
                               "capture", "--out", str(out)))  # fmt: skip
            procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ROBOTS]
            wait_for(lambda: all_present(daemon_status(c)), 60, "the daemon and its robots")
            release(c, timeout=90)
            seen: list[str] = []
            wait_for(lambda: _arrested(plans, seen) or "approach" in seen, 30, "the approach")
            assert "approach" in seen and "arrested" not in seen, seen
            world.send_signal(signal.SIGSTOP)
            time.sleep(1.5)  # the outage itself (not a wait for anything)
            world.send_signal(signal.SIGCONT)
            wait_for(lambda: _arrested(plans, seen), 60, "the arrest after the outage")
    finally:
        codes = stop_all(procs)
    assert codes == [0] * len(codes), (codes, [tail(p) for p in procs])
    run = load_run(out)
    # (stop_all ends the drivers with the daemon: one more outage after the arrest, not counted)
    t_arrest = next(p["t"] for p in phases_of(run) if p["phase"] == "arrested")
    outages = [e for e in events_of(run, "outage") if e["t"] < t_arrest]
    ends = [e for e in events_of(run, "outage_end") if e["t"] < t_arrest]
    # one outage for the stopped world (a loaded machine can add short ones: poses 0.3 s late)
    assert len(outages) >= 1 and len(ends) == len(outages), (outages, ends)
    # (the outage starts with the first two robots gone quiet; the others join it)
    assert len(set(outages[0]["data"]["robots"]) & set(ROBOTS)) >= 2, outages
    assert all(e["data"]["lost"] == [] and e["data"]["duration_s"] < 3.0 for e in ends), ends
    assert events_of(run, "robot_lost") == [], events_of(run, "robot_lost")
    lasted = [e["data"]["duration_s"] for e in ends]
    print(f"\noutages {lasted} s; arrest {t_arrest - ends[0]['t']:.1f} s after", file=sys.stderr)
