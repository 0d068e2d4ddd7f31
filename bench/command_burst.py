"""Benchmark a tick's burst of commands through a zenoh router: are they all delivered?
Prints one JSON object.

The lab's topology on loopback: a router (the hub) in its own process; the daemon's ``Bus`` a
client of it, putting one ``robot_cmd`` per robot at 20 Hz, back to back as the daemon's tick
does (``Bus.publisher(..., command=True)``); each robot's agent a zenoh session of its own (all
in one process here) subscribed to its robot's key, stamping the receipt. Two publishers, run
interleaved in this process: ``express`` (zenoh's express flag on, as before this benchmark)
and ``batched`` (``controller.io.bus.EXPRESS_COMMANDS``: today's). Each at 6 and 50 robots,
idle and with a busy process per core (at least two) at normal priority.

Per case: commands put, lost (and on how many robots), the longest run of one robot's commands
lost in a row (at 20 Hz, 6 in a row trip an agent's 0.3 s watchdog), and the latency from the
command's stamp to the agent's receipt (p50 / p99 ms, of the delivered ones).

Usage: python bench/command_burst.py [--sizes 6,50] [--seconds 8] [--loads idle,hogs]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np
import zenoh

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import controller.io.bus as bus_mod  # noqa: E402
from controller import wire  # noqa: E402
from controller.config import ZenohSection  # noqa: E402
from controller.io.bus import Bus  # noqa: E402
from tests.support.config import free_port  # noqa: E402

FLEET = "burst"
RATE_HZ = 20.0
VARIANTS = {"express": True, "batched": False}
MP = mp.get_context("spawn")  # never fork a process that has run zenoh (its threads)


def _config(endpoint: str, mode: str, listen: bool) -> zenoh.Config:
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("listen/endpoints" if listen else "connect/endpoints", json.dumps([endpoint]))
    return c


def router(endpoint: str, stop) -> None:
    """The hub: a zenoh router, nothing else."""
    session = zenoh.open(_config(endpoint, "router", listen=True))
    stop.wait()
    session.close()


def hog(stop) -> None:
    while not stop.is_set():
        pass


def agents(endpoint: str, n: int, ready, stop, out) -> None:
    """``n`` agents' sessions, each subscribed to its robot's commands: the (stamp, receipt)
    of every command received, per robot, put on ``out`` when ``stop`` is set."""
    got: list[list[tuple[int, float, float]]] = [[] for _ in range(n)]
    sessions = []
    for i in range(n):
        s = zenoh.open(_config(endpoint, "client", listen=False))

        def received(sample, i=i) -> None:
            msg = wire.decode(wire.Twist2D, sample.payload.to_bytes())
            got[i].append((msg.seq, msg.t, time.time()))

        s.declare_subscriber(wire.key("robot_cmd", FLEET, id=f"r{i + 1}"), received)
        sessions.append(s)
    ready.set()
    stop.wait()
    out.put(got)
    for s in sessions:
        s.close()


def run_case(n: int, seconds: float, express: bool, hogs: int) -> dict:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop, ready, out = MP.Event(), MP.Event(), MP.Queue()
    procs = [MP.Process(target=router, args=(endpoint, stop))]
    procs[0].start()
    time.sleep(0.5)  # the router listening before the clients connect (they retry anyway)
    procs.append(MP.Process(target=agents, args=(endpoint, n, ready, stop, out)))
    procs[-1].start()
    if not ready.wait(60):
        raise SystemExit("the agents' sessions did not open in 60 s")
    procs += [MP.Process(target=hog, args=(stop,)) for _ in range(hogs)]
    for p in procs[2:]:
        p.start()
    bus_mod.EXPRESS_COMMANDS = express  # read when the publishers are declared
    bus = Bus(ZenohSection(), FLEET, mode="client", listen=[], connect=[endpoint])
    pubs = [bus.publisher("robot_cmd", command=True, id=f"r{i + 1}") for i in range(n)]
    time.sleep(1.0)  # the subscriptions propagated to the router (a warm-up, not measured)
    ticks = int(seconds * RATE_HZ)
    t_next = time.monotonic()
    for k in range(ticks):
        now = time.time()
        for p in pubs:  # the daemon's burst: one command per robot, back to back
            p.put(wire.Twist2D(t=now, seq=k, vx=0.1))
        t_next += 1.0 / RATE_HZ
        time.sleep(max(0.0, t_next - time.monotonic()))
    time.sleep(1.0)  # the last commands' delivery (a drain, then the count)
    stop.set()
    got = out.get(timeout=30)
    for p in procs:
        p.join(timeout=10)
    bus.close()
    lat, lost, runs = [], [], []
    for rows in got:
        seqs = sorted({s for s, _, _ in rows})
        lost.append(ticks - len(seqs))
        have = np.zeros(ticks, bool)
        have[[s for s in seqs if s < ticks]] = True
        run = best = 0
        for h in have:
            run = 0 if h else run + 1
            best = max(best, run)
        runs.append(best)
        lat += [(r - t) * 1e3 for _, t, r in rows]
    lat_a = np.asarray(lat) if lat else np.zeros(1)
    return {
        "commands": ticks * n,
        "lost": int(sum(lost)),
        "robots_losing": int(sum(1 for x in lost if x)),
        "longest_run_lost": int(max(runs)),
        "latency_p50_ms": round(float(np.percentile(lat_a, 50)), 2),
        "latency_p99_ms": round(float(np.percentile(lat_a, 99)), 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="6,50")
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--loads", default="idle,hogs")
    args = ap.parse_args()
    n_hogs = max(2, os.cpu_count() or 2)
    cases = []
    for load in args.loads.split(","):
        for n in (int(x) for x in args.sizes.split(",")):
            row = {"robots": n, "load": load}
            for name, express in VARIANTS.items():  # interleaved: same machine state
                print(f"{load}, {n} robots, {name}...", file=sys.stderr, flush=True)
                row[name] = run_case(n, args.seconds, express, n_hogs if load == "hogs" else 0)
            cases.append(row)
    print(
        json.dumps(
            {
                "benchmark": "command_burst",
                "rate_hz": RATE_HZ,
                "seconds": args.seconds,
                "hogs": n_hogs,
                "load_avg": round(os.getloadavg()[0], 2),
                "cases": cases,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
