"""Time from ``fleet estop`` to every agent engaged, with the daemon alive, hung (SIGSTOP) and
dead: a hub, a daemon (mission hold) and three sim agents on 127.0.0.1 (ideal backend); then
without ``fleet hub`` (the daemon starts its own), the daemon hung.

Prints one JSON object: per case the median and max over N tries of ``elapsed_s`` (from the
tool's publication to the last agent's confirmation, as the tool reports it), of the whole
command's wall time (process start to exit, Python start-up included), and of ``fleet resume``'s
``elapsed_s`` (it first asks the holders for the latch's epoch); the load average at the end.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.config import free_port  # noqa: E402
from tests.support.lab import fleet_json, lab_config, spawn, stop_all  # noqa: E402

N = int(sys.argv[1]) if len(sys.argv) > 1 else 10


def tries(cfg: Path) -> dict:
    el, wall, res = [], [], []
    for _ in range(N):
        t0 = time.monotonic()
        code, out = fleet_json("estop", "--config", str(cfg), "--timeout", "30")
        wall.append(time.monotonic() - t0)
        assert code == 0, out
        el.append(out["elapsed_s"])
        code, out = fleet_json("resume", "--config", str(cfg), "--timeout", "30")
        assert code == 0, out
        res.append(out["elapsed_s"])
    return {
        "elapsed_median_ms": round(statistics.median(el) * 1e3, 1),
        "elapsed_max_ms": round(max(el) * 1e3, 1),
        "resume_elapsed_median_ms": round(statistics.median(res) * 1e3, 1),
        "command_wall_median_s": round(statistics.median(wall), 3),
        "tries": N,
    }


def up(c: str) -> None:
    """Until the daemon answers and sees every robot (60 s at most)."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        code, st = fleet_json("status", "--config", c, "--timeout", "1")
        if code == 0 and all(r["present"] for r in st["robots"]):
            return


def no_hub_hung(tmp: Path) -> dict:
    """No ``fleet hub``: the daemon starts its own; the e-stop with the daemon hung."""
    tmp.mkdir()
    cfg = lab_config(tmp, free_port(), robots=3)
    c = str(cfg)
    daemon = spawn(tmp / "d.txt", "daemon", "--config", c, "--mission", "hold", "--out",
                   str(tmp / "d.mcap"))  # fmt: skip
    agents = [spawn(tmp / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2", "r3")]
    try:
        up(c)
        fleet_json("resume", "--config", c, "--timeout", "60")  # the first resume (not timed)
        daemon.send_signal(signal.SIGSTOP)
        return tries(cfg)
    finally:
        daemon.send_signal(signal.SIGCONT)
        stop_all([daemon, *agents])


def main() -> int:
    tmp = Path(tempfile.mkdtemp(prefix="estop-bench-"))
    cfg = lab_config(tmp, free_port(), robots=3)
    c = str(cfg)
    procs = [spawn(tmp / "hub.txt", "hub", "--config", c)]
    out: dict = {}
    try:
        time.sleep(1.0)  # bench only: the hub's start-up (the tests wait on a handshake)
        daemon = spawn(tmp / "d.txt", "daemon", "--config", c, "--mission", "hold", "--out",
                       str(tmp / "d.mcap"))  # fmt: skip
        procs.append(daemon)
        procs += [spawn(tmp / f"{r}.txt", "driver", r, "--config", c) for r in ("r1", "r2", "r3")]
        up(c)
        # a fresh lab fails closed: the operator's first resume (not timed)
        fleet_json("resume", "--config", c, "--timeout", "20")
        out["alive"] = tries(cfg)
        daemon.send_signal(signal.SIGSTOP)
        out["hung"] = tries(cfg)
        daemon.send_signal(signal.SIGCONT)
        daemon.kill()
        daemon.wait()
        out["dead"] = tries(cfg)
    finally:
        stop_all(procs)
    out["no_hub_hung"] = no_hub_hung(tmp / "nohub")
    out["loadavg"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
