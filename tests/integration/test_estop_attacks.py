"""Issue 22: the e-stop only operators lift, that survives every restart - as separate processes
on 127.0.0.1 (``fleet hub``, the daemon, robot agents, the ``fleet estop|resume`` tools).

- under the lab profile (passwords + the lab ACL), robot r1's own identity answers the latch
  query on its own key "released, stamped now + 1e6 s": nobody is released;
- on the open default, an old operator release put again (replayed), and one stamped in the
  future, are refused;
- the e-stop survives a restart of the hub and a full restart (every process);
- a fresh daemon with no latch holder comes up stopped, and stays stopped until an operator's
  release; without a hub the daemon keeps the latch itself (a restarted daemon comes up
  engaged).
"""

from __future__ import annotations

import signal
import socket
import threading
import time

import pytest

from controller import wire
from controller.config import ZenohIdentity, load_config
from controller.io.bus import Bus, BusError
from tests.support.config import base_config_dict, write_toml
from tests.support.lab import (
    connect_client,
    fleet_json,
    lab_config,
    spawn,
    status,
    stop_all,
    tail,
)
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

USERS = ["controller", "operator", "r1", "r2"]


def _kill(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait()


def _kept_engaged(tmp_path, holder: str) -> bool:
    """Whether ``holder``'s latch file says engaged (the handshake before a kill)."""
    path = tmp_path / "state" / f"estop-lab-{holder}.json"
    return path.exists() and wire.decode(wire.EStop, path.read_bytes()).engaged


def _states(bus, timeout: float = 1.0) -> dict[str, wire.EStop]:
    """Every holder's latch by ``role/id``, the forged answers (source "forged") left out."""
    out = {}
    for key, msg in bus.query_replies(bus.estop_wildcard(), wire.EStop, timeout):
        parsed = wire.parse_key(key, bus.fleet)
        if parsed is not None and msg.source != "forged":
            out[f"{parsed.parts['role']}/{parsed.id}"] = msg
    return out


def _holders_engaged(bus, names) -> bool:
    states = _states(bus)
    return all(n in states and states[n].engaged for n in names)


def _resume(cfg, *extra: str) -> dict:
    code, out = fleet_json("resume", "--config", str(cfg), "--timeout", "30", *extra)
    assert code == 0 and out["confirmed"] is True, out
    return out


def _estop(cfg, *extra: str) -> dict:
    code, out = fleet_json("estop", "--config", str(cfg), "--timeout", "30", *extra)
    assert code == 0 and out["confirmed"] is True, out
    return out


class _Counter:
    def __init__(self) -> None:
        self.n = 0
        self.lock = threading.Lock()

    def bump(self) -> None:
        with self.lock:
            self.n += 1


def _secure_lab(tmp_path, port):
    for u in USERS:
        (tmp_path / f"{u}.pw").write_text(f"pw-of-{u}\n")
    (tmp_path / "users.txt").write_text("".join(f"{u}:pw-of-{u}\n" for u in USERS))
    cfg = base_config_dict()
    cfg["zenoh"] = {
        "mode": "peer",
        "listen": [f"tcp/127.0.0.1:{port}"],
        "user": "controller",
        "password_file": "controller.pw",
        "auth_dictionary": "users.txt",
        "acl": "lab",
        "operators": ["operator"],
    }
    cfg["robots"] = cfg["robots"][:2]
    for r in cfg["robots"]:
        r.update(zenoh_user=r["id"], zenoh_password_file=f"{r['id']}.pw")
    cfg["sim"]["backend"] = "ideal"
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "secure.toml", cfg)


def _as(tmp_path, user: str) -> list[str]:
    return ["--user", user, "--password-file", str(tmp_path / f"{user}.pw")]


def test_a_robots_released_answer_stamped_in_the_future_releases_nobody(tmp_path, port):
    conf = _secure_lab(tmp_path, port)
    c = str(conf)
    procs = [spawn(tmp_path / "hub.txt", "hub", "--config", c)]
    try:
        cfg = load_config(conf)
        watcher = _client(cfg, "operator", tmp_path, port)
        with watcher:
            daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")
            procs.append(spawn(tmp_path / "daemon.txt", *daemon_args, str(tmp_path / "d.mcap")))
            procs += [
                spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in cfg.robot_ids
            ]
            wait_for(lambda: status(conf).get("ok"), 40, "the daemon")
            _resume(conf, *_as(tmp_path, "operator"))  # the operator starts the fleet
            _estop(conf, *_as(tmp_path, "operator"))  # ... and stops it
            holders = ["hub/main", "controller/main", "robot/r1", "robot/r2"]
            wait_for(lambda: _holders_engaged(watcher, holders), 10, "every holder engaged")

            # r1's own credentials: one answer on its own latch key, released, far in the future
            asked = _Counter()

            def forged() -> wire.EStop:
                asked.bump()
                return wire.EStop(t=time.time() + 1e6, engaged=False, source="forged")

            attacker = _client(cfg, "r1", tmp_path, port)
            with attacker:
                attacker.serve("estop_state", forged, role="robot", id="r1")
                # the handshake: the hub and both agents ask every 2 s; the old code freed
                # everyone within 2 s of the forged answer. Wait for 8 answers (≈ 3 rounds).
                wait_for(lambda: asked.n >= 8, 20, "the forged answer asked for")
                assert _holders_engaged(watcher, holders), _states(watcher)
                st = status(conf)
                assert st["estop"] is True, st
                # a re-pressed e-stop is confirmed and stays (it was undone 0.45-2.5 s later)
                _estop(conf, *_as(tmp_path, "operator"))
                n = asked.n
                wait_for(lambda: asked.n >= n + 8, 20, "more forged answers asked for")
                assert _holders_engaged(watcher, holders), _states(watcher)
                assert status(conf)["estop"] is True
            # only the operator lifts it
            _resume(conf, *_as(tmp_path, "operator"))
            assert status(conf)["estop"] is False
    finally:
        codes = stop_all(procs)
    assert all(code == 0 for code in codes), (codes, [tail(p) for p in procs])


def _client(cfg, user: str, tmp_path, port: int) -> Bus:
    """A session as ``user`` (its password file), retried until the hub listens."""
    ident = ZenohIdentity(path="test", user=user, password_file=str(tmp_path / f"{user}.pw"))
    box: list[Bus] = []

    def opened() -> bool:
        try:
            box.append(
                Bus(
                    cfg.zenoh,
                    cfg.fleet.name,
                    mode="client",
                    listen=[],
                    connect=[f"tcp/127.0.0.1:{port}"],
                    identity=ident,
                )
            )
        except BusError:
            return False
        return True

    wait_for(opened, 20, f"a session as {user}")
    return box[0]


def test_a_replayed_or_future_stamped_operator_release_is_refused(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    procs = [spawn(tmp_path / "hub.txt", "hub", "--config", c)]
    try:
        bus = connect_client(port, "the hub")
        with bus:
            recorded = bus.subscribe_topic("estop")
            procs += [
                spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")
            ]
            _resume(cfg)
            release = recorded.get(timeout=5.0)  # an eavesdropper records the operator's resume
            assert release is not None and release.msg.engaged is False
            _estop(cfg)
            holders = ["hub/main", "robot/r1", "robot/r2"]
            wait_for(lambda: _holders_engaged(bus, holders), 10, "every holder engaged")
            pub = bus.publisher("estop")
            pub.put(release.msg)  # the replay
            future = wire.EStop(t=time.time() + 1e6, engaged=False, source="someone")
            pub.put(future)  # a release stamped in the future (and no epoch)

            # handshake: every holder logs both refusals, or one holder obeyed (the old code)
            def refused_or_released() -> bool:
                if any(not st.engaged for st in _states(bus, 0.5).values()):
                    return True
                return all(tail(p, 20000).count("refused") >= 2 for p in procs)

            wait_for(refused_or_released, 10, "the holders taking in both releases")
            assert _holders_engaged(bus, holders), _states(bus)
    finally:
        codes = stop_all(procs)
    assert all(code == 0 for code in codes), (codes, [tail(p) for p in procs])


def test_an_old_resume_replayed_after_the_latch_files_are_lost_releases_nobody(tmp_path, port):
    """Issue 31 item 6: an eavesdropper records the operator's resume; later every process is
    killed and the state folder lost (a new disk), so every holder comes back fresh (epoch 0)
    and the recording's epoch is above theirs. Replayed, it releases nobody (stamped long
    before the holders' clocks: refused, counted); the operator's own resume then releases."""
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")

    def start(n: int) -> list:
        out = [spawn(tmp_path / f"hub{n}.txt", "hub", "--config", c)]
        out.append(spawn(tmp_path / f"d{n}.txt", *daemon_args, str(tmp_path / f"d{n}.mcap")))
        out += [spawn(tmp_path / f"{r}-{n}.txt", "driver", r, "--config", c) for r in ("r1", "r2")]
        return out

    procs = start(1)
    try:
        with connect_client(port, "the hub") as bus:
            recorded = bus.subscribe_topic("estop")
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
            _resume(cfg)
            release = recorded.get(timeout=5.0)  # the recording
            assert release is not None and release.msg.engaged is False
        _kill(procs)
        for f in (tmp_path / "state").glob("estop-*"):
            f.unlink()  # the latch files lost
        procs = start(2)
        with connect_client(port, "the hub after the restart") as bus:
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon after the restart")
            wait_for(lambda: _states(bus, 0.5) == {}, 20, "every holder fresh (unknown)")
            # a fresh holder answers nothing, so {} held before the agents were up too: their
            # liveliness tokens come after their e-stop subscriptions (the replay reaches them)
            up = lambda: sorted(bus.alive_ids("robot", 0.5)) == ["r1", "r2"]  # noqa: E731
            wait_for(up, 30, "both agents up")
            # the recording is older than the clocks' skew by now (the restart took longer)
            assert time.time() - release.msg.t > load_config(c).fleet.max_clock_skew
            bus.publisher("estop").put(release.msg)  # the replay

            def taken_in() -> bool:  # handshake: each process refused it, or one obeyed
                if any(not st.engaged for st in _states(bus, 0.5).values()):
                    return True
                return all("release stamped too far" in tail(p, 20000) for p in procs)

            wait_for(taken_in, 10, "every holder taking in the replay")
            assert _states(bus) == {}, _states(bus)  # still unknown: robots held
            st = status(cfg)
            assert st["counters"]["estop_unknown"] == 1, st
            assert st["counters"]["estop_stale_releases"] == 1, st
            out = _resume(cfg)  # the operator's own release goes through
            assert out["daemon_confirmed"] and out["hub_confirmed"], out
    finally:
        codes = stop_all(procs)
    assert all(code == 0 for code in codes), (codes, [tail(p) for p in procs])


def test_the_estop_survives_a_hub_restart_and_a_full_restart(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")
    hub = spawn(tmp_path / "hub.txt", "hub", "--config", c)
    procs = [hub]
    try:
        bus = connect_client(port, "the hub")
        with bus:
            procs.append(spawn(tmp_path / "d1.txt", *daemon_args, str(tmp_path / "d1.mcap")))
            procs += [
                spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")
            ]
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
            _resume(cfg)
            _estop(cfg)
            holders = ["hub/main", "controller/main", "robot/r1", "robot/r2"]
            wait_for(lambda: _holders_engaged(bus, holders), 10, "every holder engaged")
            wait_for(lambda: _kept_engaged(tmp_path, "hub"), 10, "the hub's file")
            wait_for(lambda: _kept_engaged(tmp_path, "controller"), 10, "the daemon's file")
        # the hub killed and restarted: it comes back engaged, from its file
        _kill([hub])
        procs.append(spawn(tmp_path / "hub2.txt", "hub", "--config", c))
        bus = connect_client(port, "the restarted hub")
        with bus:
            wait_for(lambda: "hub/main" in _states(bus, 0.5), 20, "the hub's latch")
            assert _states(bus)["hub/main"].engaged
            wait_for(lambda: _holders_engaged(bus, holders), 20, "every holder engaged")
        # every process killed at once, then all started again: still engaged everywhere
        _kill(procs)
        procs = [spawn(tmp_path / "hub3.txt", "hub", "--config", c)]
        bus = connect_client(port, "the hub after a full restart")
        with bus:
            procs.append(spawn(tmp_path / "d2.txt", *daemon_args, str(tmp_path / "d2.mcap")))
            procs += [
                spawn(tmp_path / f"{r}-2.txt", "driver", r, "--config", c) for r in ("r1", "r2")
            ]
            wait_for(lambda: status(cfg).get("ok"), 40, "the daemon after a full restart")
            wait_for(lambda: _holders_engaged(bus, holders), 20, "every holder engaged")
            st = status(cfg)
            assert st["estop"] is True and st["counters"]["estop_unknown"] == 0, st
            out = _resume(cfg)
            assert out["daemon_confirmed"] and out["hub_confirmed"], out
    finally:
        codes = stop_all(procs)
    assert all(code == 0 for code in codes), (codes, [tail(p) for p in procs])


def test_a_fresh_daemon_without_holders_stays_stopped_and_keeps_the_latch(tmp_path, port):
    cfg = lab_config(tmp_path, port, robots=1)
    c = str(cfg)
    daemon_args = ("daemon", "--config", c, "--mission", "hold", "--out")
    procs = [spawn(tmp_path / "d1.txt", *daemon_args, str(tmp_path / "d1.mcap"))]
    try:
        wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
        st = status(cfg)
        assert st["estop"] is True and st["counters"]["estop_unknown"] == 1, st
        # it gives up waiting for an answer after 2 s: still stopped (the old code went on
        # released). Handshake: its log says it gave up waiting.
        wait_for(lambda: "no holder answered" in tail(procs[0]), 20, "the daemon giving up")
        assert status(cfg)["estop"] is True
        procs.append(spawn(tmp_path / "r1.txt", "driver", "r1", "--config", c))
        _resume(cfg)  # the operator releases it (the agent too, fresh as well)
        assert status(cfg)["estop"] is False
        _estop(cfg)
        wait_for(lambda: _kept_engaged(tmp_path, "controller"), 10, "the daemon's file")
        # no hub: the daemon is the keeper; restarted, it comes up engaged from its file
        _kill(procs[:1])
        procs.append(spawn(tmp_path / "d2.txt", *daemon_args, str(tmp_path / "d2.mcap")))
        wait_for(lambda: status(cfg).get("ok"), 40, "the restarted daemon")
        st = status(cfg)
        assert st["estop"] is True and st["counters"]["estop_unknown"] == 0, st
        out = _resume(cfg)
        assert out["daemon_confirmed"], out
    finally:
        codes = stop_all(procs)
    assert all(code in (0, -9) for code in codes), (codes, [tail(p) for p in procs])


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_without_a_hub_the_estop_reaches_the_agents_with_the_daemon_hung(tmp_path, port):
    """No ``fleet hub`` started: the daemon starts one as its own child process and joins it,
    so the e-stop goes through with the daemon hung (it failed after 10.5 s before); killed,
    the daemon takes its hub with it."""
    cfg = lab_config(tmp_path, port, robots=2)
    c = str(cfg)
    daemon = spawn(tmp_path / "d.txt", "daemon", "--config", c, "--mission", "hold",
                   "--out", str(tmp_path / "d.mcap"))  # fmt: skip
    procs = [daemon] + [
        spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2")
    ]
    try:
        wait_for(lambda: status(cfg).get("ok"), 40, "the daemon")
        _resume(cfg)
        daemon.send_signal(signal.SIGSTOP)
        out = _estop(cfg)
        assert out["agents_confirmed"] == ["r1", "r2"] and out["hub_confirmed"], out
        assert not out["daemon_confirmed"], out
        daemon.send_signal(signal.SIGCONT)
        wait_for(lambda: status(cfg).get("estop") is True, 15, "the resumed daemon stopped")
        _resume(cfg)
        _kill([daemon])
        wait_for(lambda: not _listening(port), 10, "the daemon's hub gone with it")
    finally:
        codes = stop_all(procs)
    assert codes[0] == -9 and all(code == 0 for code in codes[1:]), (
        codes,
        [tail(p) for p in procs],
    )
