"""How long a hub restart takes to heal: ``fleet hub``, ``fleet world`` (ideal backend) and six sim
agents (each its own ``fleet driver`` process, its robot a body of that world: the lab's path,
``sim.world = "process"``) on 127.0.0.1, a watcher session in place of the daemon (a client of
the hub, as the daemon is). The hub is killed (SIGKILL) and started again at once; measured
from the kill: ``back_s``, when every robot's liveliness token is seen again and a pose of each
has arrived after it (what the daemon needs to take the robots back: ``fleet.outage_grace``
must cover it). Repeated ``--tries`` times, for each ``zenoh.reconnect_s`` in ``--reconnect``
(a lost endpoint retried after 0.25 s, then doubling up to that cap; 0: zenoh's own back-off,
1 s doubling up to 4 s), optionally with ``--load N`` busy processes on the machine.

Prints one JSON object: per setting the median and max of ``back_s``, of ``hub_up_s`` (the
restarted hub listening) and of ``tokens_back_s`` (every robot's token seen again: the
sessions reconnected), the load average at the end.

Usage: python bench/hub_restart.py [--tries 5] [--reconnect 1.0,0] [--load 0]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controller import wire  # noqa: E402
from controller.config import load_config  # noqa: E402
from controller.io.bus import Bus  # noqa: E402
from tests.support.config import free_port  # noqa: E402
from tests.support.lab import lab_config, spawn, stop_all  # noqa: E402
from tests.support.wait import wait_for  # noqa: E402

ROBOTS = 6


def _burn() -> None:
    while True:
        pass


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


class Watch:
    """Robots' tokens and poses as the daemon would see them (a client of the hub)."""

    def __init__(self, bus: Bus, ids: list[str]) -> None:
        self.lock = threading.Lock()
        self.alive = dict.fromkeys(ids, False)
        self.back: dict[str, float] = {}  # token back, time
        self.pose_after: dict[str, float] = {}  # first pose after the token came back
        bus.watch_alive("robot", self._token)
        self.poses = bus.subscribe_topic("robot_pose")

    def _token(self, ident: str, alive: bool) -> None:
        with self.lock:
            self.alive[ident] = alive
            if alive:
                self.back[ident] = time.monotonic()

    def reset(self) -> None:
        with self.lock:
            self.back.clear()
            self.pose_after.clear()

    def healed(self) -> bool:
        for item in self.poses.drain():
            rid = wire.parse_key(item.key).id
            with self.lock:
                if rid in self.back and rid not in self.pose_after:
                    self.pose_after[rid] = time.monotonic()
        with self.lock:
            return all(self.alive.values()) and len(self.pose_after) == len(self.alive)


def one_setting(reconnect: float, tries: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(os.environ.get("BENCH_KEEP") or d)  # BENCH_KEEP=dir: keep the processes' logs
        tmp.mkdir(parents=True, exist_ok=True)
        port = free_port()
        cfg_path = lab_config(tmp, port, robots=ROBOTS)
        text = cfg_path.read_text().replace("[zenoh]\n", f"[zenoh]\nreconnect_s = {reconnect}\n")
        # the lab's path: one world process, the agents drive its bodies over the bus (an agent
        # with a world of its own steps the whole room: six of them outran 2 cores, and their
        # poses fell seconds behind whatever the hub did)
        text = text.replace("[sim]\n", '[sim]\nworld = "process"\n')
        cfg_path.write_text(text)
        cfg = load_config(str(cfg_path))
        c = str(cfg_path)
        hub = spawn(tmp / "hub0.txt", "hub", "--config", c)
        procs = [hub]
        wait_for(lambda: _listening(port), 30, "the hub")
        procs.append(spawn(tmp / "world.txt", "world", "--config", c))
        procs += [spawn(tmp / f"{r}.txt", "driver", r, "--config", c) for r in cfg.robot_ids]
        back, up, tokens = [], [], []
        try:
            hub_ep = [f"tcp/127.0.0.1:{port}"]
            with Bus(cfg.zenoh, cfg.fleet.name, listen=[], connect=hub_ep) as bus:
                w = Watch(bus, list(cfg.robot_ids))
                wait_for(w.healed, 60, "every robot present")
                for k in range(tries):
                    w.reset()
                    t0 = time.monotonic()
                    hub.kill()
                    hub.wait()
                    wait_for(lambda: not any(w.alive.values()), 30, "the robots gone")
                    hub = spawn(tmp / f"hub{k + 1}.txt", "hub", "--config", c)
                    procs.append(hub)
                    wait_for(lambda: _listening(port), 30, "the restarted hub")
                    up.append(time.monotonic() - t0)
                    wait_for(w.healed, 60, "every robot back")
                    back.append(max(w.pose_after.values()) - t0)
                    tokens.append(max(w.back.values()) - t0)
        finally:
            stop_all(procs)
    return {
        "reconnect_s": reconnect,
        "tries": tries,
        "back_s": {"median": round(statistics.median(back), 3), "max": round(max(back), 3)},
        "hub_up_s": {"median": round(statistics.median(up), 3), "max": round(max(up), 3)},
        "tokens_back_s": {
            "median": round(statistics.median(tokens), 3),
            "max": round(max(tokens), 3),
        },
    }


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tries", type=int, default=5)
    ap.add_argument("--reconnect", default="1.0,0")
    ap.add_argument("--load", type=int, default=0)
    a = ap.parse_args()
    burners = [multiprocessing.Process(target=_burn, daemon=True) for _ in range(a.load)]
    for b in burners:
        b.start()
    try:
        rows = [one_setting(float(r), a.tries) for r in a.reconnect.split(",")]
    finally:
        for b in burners:
            b.terminate()
    print(
        json.dumps(
            {
                "robots": ROBOTS,
                "load": a.load,
                "settings": rows,
                "loadavg_1m": round(os.getloadavg()[0], 2),
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
