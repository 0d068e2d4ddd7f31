"""Benchmark the lab loop: the daemon's tick, command latency and the time to notice a dead robot.
Prints one JSON object.

For 6, 20 and 50 robots (ideal sim backend, zenoh on a free 127.0.0.1 port), with the ``hold``
mission and with the ``transport`` mission (``--missions hold,transport``: the crate of
fleet.toml with its goal, as a motion-capture system reports it standing still — the agents'
worlds hold only their robots — so the route, the re-arrangement sets and a local plan every
interval are asked of the planner worker, a process as in ``fleet daemon``, throughout):

- the daemon's tick time (sample → estimate → plan → safety → publish), p50/p99 in ms, the
  daemon's node run in this process exactly as ``fleet daemon`` wires it (listening session,
  ``ControllerNode``, the 20 Hz rate keeper);
- command latency, p50/p99 in ms: the command's stamp ``t`` (the tick time, taken before the
  tick's stages; the daemon then publishes the robots' commands one after the other) against
  the agent's receive time (``time.time()`` in zenoh's callback), same machine clock;
- the time from a robot's disappearance (``kill -9`` of its agent process) to the daemon
  reporting it not present (its liveliness token withdrawn);
- transport: the planner worker's latency per planner (p50/p99 s) and the tick with the worker
  as a thread instead (``--thread-too``: what the GIL does to the tick).

Agents run as separate processes (this file with ``--host``): robot r1 alone in its own process
(the one killed), the others up to ``--per-host`` per process, each with its own zenoh session
and ``Agent``, sharing one ideal world per process (50 agent processes are too heavy for a
2-core machine). The machine's load average is reported: the figures are noisy on a shared one.

Usage: python bench/loop.py [--sizes 6,20,50] [--seconds 10] [--per-host 10]
[--missions hold,transport] [--thread-too]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controller.config import FleetConfig, parse_config  # noqa: E402
from controller.io.bus import Bus  # noqa: E402

STARTUP_S = 60.0  # s: bound on waiting for every robot to be present
DETECT_S = 15.0  # s: bound on waiting for a killed robot to be noticed


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def config_data(n: int, port: int) -> dict:
    """The shipped fleet.toml with ``n`` omni robots in two rows along the south wall, on the
    ideal backend, zenoh on ``port``."""
    with open(ROOT / "fleet.toml", "rb") as f:
        data = tomllib.load(f)
    proto = dict(data["robots"][0], kind="omni", driver="sim")
    per_row = 25
    data["robots"] = [
        dict(
            proto,
            id=f"r{i + 1}",
            start=[0.6 + 0.46 * (i % per_row), 0.6 + 0.6 * (i // per_row), 0.0],
        )
        for i in range(n)
    ]
    data["sim"]["backend"] = "ideal"
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["log"] = {"dir": str(ROOT / "runs")}
    return data


# --------------------------------------------------------------------------- agent host


class _Timed:
    """An agent's command inbox that notes each command's latency (receive time − stamp)."""

    def __init__(self, inner, out: list) -> None:
        self._inner, self._out = inner, out

    def drain(self):
        items = self._inner.drain()
        for it in items:
            self._out.append((it.recv_time, it.recv_time - it.msg.t))
        return items

    def qsize(self) -> int:
        return self._inner.qsize()


def host(data_path: str, ids: list[str], out_path: str, limit_s: float) -> None:
    """Run the agents of ``ids`` on one ideal world until SIGTERM (or ``limit_s``); write the
    latencies to ``out_path``."""
    from controller.io.ratekeeper import Ratekeeper
    from controller.runtime.agent_runner import robot_bus
    from controller.runtime.wiring import make_hub
    from drivers.agent import Agent, AgentParams
    from drivers.base import capabilities_of
    from drivers.sim import SimDriver

    cfg = parse_config(json.loads(Path(data_path).read_text()), data_path)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    # the world only moves these robots for their agents: one physics step per pose sample (at
    # the config's 240 Hz, six hosts' worlds took most of the machine from the daemon measured;
    # the poses still come at sim.pose_rate_hz)
    sim = dataclasses.replace(cfg.sim, timestep=1.0 / max(cfg.sim.pose_rate_hz, cfg.fleet.rate_hz))
    mine = dataclasses.replace(cfg, robots=tuple(cfg.robot(r) for r in ids), sim=sim)
    hub = make_hub(mine)
    wall0 = time.time()
    lat: list[tuple[float, float]] = []
    buses, agents = [], []
    try:
        for rid in ids:
            robot = cfg.robot(rid)
            driver = SimDriver(hub, rid, capabilities_of(robot), time_offset=wall0)
            driver.connect(timeout=1.0)
            bus = robot_bus(cfg, rid)
            buses.append(bus)
            params = AgentParams(rid, cfg.fleet.name, cfg.fleet.cmd_ttl, cfg.fleet.max_clock_skew)
            agent = Agent(bus, driver, params)
            agent._cmds = _Timed(agent._cmds, lat)  # noqa: SLF001 - the bench's probe
            agents.append(agent)
        rk = Ratekeeper(cfg.fleet.rate_hz)
        while not stop.is_set() and time.time() - wall0 < limit_s:
            rk.keep_time()
            now = time.time()
            hub.advance_to(now - wall0)
            for a in agents:
                a.step(now)
    finally:
        for b in buses:
            b.close()
        hub.world.close()
        Path(out_path).write_text(json.dumps(lat))


# --------------------------------------------------------------------------- the daemon side


def _percentiles(values, scale: float = 1e3) -> dict:
    a = np.asarray(values, dtype=float) * scale
    if a.size == 0:
        return {"p50": None, "p99": None, "n": 0}
    return {
        "p50": round(float(np.percentile(a, 50)), 3),
        "p99": round(float(np.percentile(a, 99)), 3),
        "n": int(a.size),
    }


def _mission(kind: str, cfg: FleetConfig, thread: bool):
    """(mission, planner worker or None) as ``fleet daemon`` builds them."""
    from controller.mission.basic import HoldMission
    from controller.mission.factory import build_mission
    from controller.runtime.planner import PlannerWorker

    if kind == "hold":
        return HoldMission(len(cfg.robots)), None
    planners = PlannerWorker.for_config(cfg, lockstep=False, process=not thread)
    return build_mission(cfg, "transport", planners=planners), planners


def _object_pose(bus, cfg: FleetConfig):
    """The crate at its start, as a motion-capture system would report it (30 Hz is plenty:
    one per tick)."""
    from controller import wire

    pub = bus.publisher("object_pose")
    x, y, th = cfg.object.start
    seq = [0]

    def put(now: float) -> None:
        seq[0] += 1
        pub.put(wire.PoseMeasurement(t=now, seq=seq[0], x=x, y=y, theta=th, source="mocap"))

    return put


def run_size(
    n: int, seconds: float, per_host: int, workdir: Path, kind: str = "hold", thread=False
) -> dict:
    from controller.io.ratekeeper import Ratekeeper
    from controller.runtime.node import ControllerNode
    from controller.runtime.wiring import make_estimator

    port = free_port()
    data = config_data(n, port)
    data_path = workdir / f"loop-{n}.json"
    data_path.write_text(json.dumps(data))
    cfg: FleetConfig = parse_config(data, str(data_path))
    gone_at: dict[str, float] = {}

    ids = list(cfg.robot_ids)
    groups = [ids[:1]] + [ids[i : i + per_host] for i in range(1, n, per_host)]
    procs: list[tuple[subprocess.Popen, Path]] = []
    ticks: list[float] = []
    out: dict = {"robots": n, "mission": kind, "agent_processes": len(groups)}
    if kind != "hold":
        out["planner"] = "thread" if thread else "process"
    mission, planners = _mission(kind, cfg, thread)
    with Bus(cfg.zenoh, cfg.fleet.name) as bus:
        # a robot's liveliness token withdrawn: when (the kill -9 below)
        bus.watch_alive("robot", lambda rid, alive: alive or gone_at.setdefault(rid, time.time()))
        node = ControllerNode(  # as fleet daemon wires it: poses read from a zenoh ring per key
            cfg,
            bus,
            mission,
            make_estimator(cfg),
            clock=time.perf_counter,
            planners=planners,
            rings=True,
        )
        mocap = _object_pose(bus, cfg)
        try:
            for g, members in enumerate(groups):
                res = workdir / f"lat-{n}-{g}.json"
                log = open(workdir / f"host-{n}-{g}.txt", "w")  # noqa: SIM115 - closed below
                limit = STARTUP_S + seconds + DETECT_S + 30
                p = subprocess.Popen(
                    [sys.executable, __file__, "--host", str(data_path), ",".join(members)]
                    + ["--out", str(res), "--limit", str(limit)],
                    stdout=log,
                    stderr=log,
                    cwd=ROOT,
                )
                log.close()
                procs.append((p, res))
            rk = Ratekeeper(cfg.fleet.rate_hz)
            t_start = time.monotonic()
            phase, t_measure, t_end, t_kill = "startup", 0.0, 0.0, 0.0
            while True:
                rk.keep_time()
                now = time.time()
                mocap(now)
                a = time.perf_counter()
                node.tick(now)
                b = time.perf_counter()
                mono = time.monotonic()
                if phase == "startup":
                    if node.present.all():
                        phase, t_measure = "measure", now + 1.0  # 1 s of warm-up
                        out["startup_s"] = round(mono - t_start, 2)
                    elif mono - t_start > STARTUP_S:
                        raise RuntimeError(f"only {int(node.present.sum())}/{n} robots present")
                elif phase == "measure":
                    if now >= t_measure:
                        ticks.append(b - a)
                    if now >= t_measure + seconds:
                        phase, t_end = "kill", now
                elif phase == "kill":
                    t_kill = time.time()
                    procs[0][0].send_signal(signal.SIGKILL)
                    phase = "detect"
                elif phase == "detect":
                    if "r1" in gone_at or mono - t_start > STARTUP_S + seconds + DETECT_S:
                        break
            out["late_ticks"] = rk.lagged
            out["phase_at_end"] = node.phase
        finally:
            if planners is not None:
                out["plan_latency_s"] = planners.summary()
                planners.close()
            for p, _ in procs:
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
            for p, _ in procs:
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
    lat = []
    for _, res in procs[1:]:  # r1's host was killed: it wrote nothing
        if res.exists():
            lat += [d for t, d in json.loads(res.read_text()) if t_measure <= t <= t_end]
    out["tick_ms"] = _percentiles(ticks)
    out["command_latency_ms"] = _percentiles(lat)
    out["kill9_to_not_present_ms"] = (
        round((gone_at["r1"] - t_kill) * 1e3, 1) if "r1" in gone_at else None
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="6,20,50")
    ap.add_argument("--missions", default="hold,transport")
    ap.add_argument("--thread-too", action="store_true", help="transport with a thread worker")
    ap.add_argument(
        "--seconds", type=float, default=10.0, help="seconds of measured ticks per size"
    )
    ap.add_argument("--per-host", type=int, default=10, help="agents per agent process")
    ap.add_argument("--host", nargs=2, metavar=("CONFIG_JSON", "IDS"), help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    ap.add_argument("--one", help=argparse.SUPPRESS)  # KIND,N,THREAD: one case, JSON out
    ap.add_argument("--limit", type=float, default=120.0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.host:
        host(args.host[0], args.host[1].split(","), args.out, args.limit)
        return
    import tempfile

    load0 = os.getloadavg()
    results = []
    if args.one:  # one case, in this fresh process (see below)
        kind, n, thread = args.one.split(",")
        with tempfile.TemporaryDirectory(prefix="bench-loop-") as tmp:
            res = run_size(int(n), args.seconds, args.per_host, Path(tmp), kind, thread == "1")
        print(json.dumps(res))
        return
    # each case in a process of its own: in one process the cases after the first ran 3-4x
    # slower (20 robots, hold: tick p50 59-90 ms after the 6-robot case, 16 ms alone)
    for kind in args.missions.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            for thread in [0, 1] if kind == "transport" and args.thread_too else [0]:
                log(f"{kind} at {n} robots" + (" (planner thread)" if thread else ""))
                one = f"{kind},{n},{thread}"
                cmd = [sys.executable, __file__, "--one", one, "--seconds", str(args.seconds)]
                out = subprocess.run(
                    cmd + ["--per-host", str(args.per_host)], cwd=ROOT, stdout=subprocess.PIPE
                )  # fmt: skip
                if out.returncode != 0:
                    raise SystemExit(f"bench/loop.py --one {one} failed ({out.returncode})")
                results.append(json.loads(out.stdout))
    print(
        json.dumps(
            {
                "bench": "loop",
                "rate_hz": 20.0,
                "missions": args.missions.split(","),
                "backend": "ideal",
                "cores": os.cpu_count(),
                "load_avg_1_5_15_start": [round(x, 2) for x in load0],
                "load_avg_1_5_15_end": [round(x, 2) for x in os.getloadavg()],
                "agents": f"r1 alone in its own process (the one killed), the others "
                f"{args.per_host} per process, one zenoh session each (50 processes are too "
                "heavy for 2 shared cores)",
                "latency": "command stamp t (tick time, before the stages) to the agent's "
                "receive time, same clock",
                "plans": "transport: route, re-arrangement sets and local plans are asked of "
                "the planner worker throughout (the crate stands still: nobody pushes it in "
                "the agents' worlds); plan_latency_s per planner",
                "sizes": results,
            }
        )
    )


if __name__ == "__main__":
    main()
