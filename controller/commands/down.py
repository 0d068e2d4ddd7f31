"""``fleet down [--config F] [--wait] [--timeout S] [--json]``: stop a lab ``fleet up
--detach`` started.

Without ``--wait`` the lab stops now: the e-stop first (every robot stopped), then the daemon
(its MCAP closed whole), the agents, the world and the hub. With ``--wait`` it first waits for
the job's end (the lab stops itself then). Either way it prints the lab's verdict line and exits
with the job's code: 0 when the job did what the config asks, 1 when it failed or was stopped
(or no lab of the fleet ever ran here).
"""

from __future__ import annotations

import os
import signal
import sys
import time

from controller.commands import add_config_argument, config_path

EXAMPLES = """examples:
  fleet down --config lab.toml            # stop the lab now (e-stop first)
  fleet down --config lab.toml --wait     # wait for the job's end, then its verdict
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument(
        "--wait", action="store_true", help="wait for the job's end before stopping the lab"
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=0.0,
        help="--wait: stop the lab anyway after S seconds (0: wait as long as the job runs)",
    )
    parser.add_argument("--json", action="store_true", help="print the lab's outcome as JSON")


def _wait_exit(pid: int, timeout: float) -> bool:
    """Whether the process ``pid`` ended within ``timeout`` s (0: no limit)."""
    from controller.runtime.lab import pid_alive

    deadline = time.monotonic() + timeout if timeout > 0 else None
    while pid_alive(pid):
        if deadline is not None and time.monotonic() > deadline:
            return False
        time.sleep(0.2)  # polling the supervisor's process for its exit (it is not our child)
    return True


def run(args) -> int:
    from controller.cli import emit_json
    from controller.config import load_config
    from controller.runtime.lab import read_state, state_path

    cfg = load_config(config_path(args))
    path = state_path(cfg)
    state = read_state(path)
    if state is None:
        print(f"fleet down: no lab of fleet {cfg.fleet.name!r} ran here ({path})", file=sys.stderr)
        if args.json:
            emit_json({"ok": False, "status": "none", "error": f"no lab state in {path}"})
        return 1
    pid = int(state.get("pid", 0))
    if args.wait and not _wait_exit(pid, args.timeout):
        print(f"fleet down: the job still runs after {args.timeout:g} s: stopping the lab")
    if pid and _signal(pid):
        _wait_exit(pid, 120.0)
    state = read_state(path) or state
    orphans = _stop_orphans(state)
    if orphans:
        print(
            f"fleet down: the lab's supervisor was gone; stopped its {len(orphans)} processes "
            f"({', '.join(orphans)}): their agents' watchdogs stop the robots",
            file=sys.stderr,
        )
    result = state.get("outcome") or {
        "status": "stopped",
        "exit": 1,
        "verdict": "STOPPED: the lab ended without a verdict (see its logs)",
        "run_dir": state.get("run_dir"),
    }
    if args.json:
        emit_json(result)
    else:
        print(result["verdict"])
        print(f"logs: {result.get('run_dir')}")
    return int(result.get("exit", 1))


def _stop_orphans(state: dict) -> list[str]:
    """The parts of a lab whose supervisor died (SIGKILL, a crash) still running: SIGTERM in
    the lab's stop order (daemon, agents, world, hub), each waited for. Returns their names."""
    from controller.runtime.lab import pid_alive

    parts = state.get("parts") or {}
    order = sorted(
        parts.items(),
        key=lambda kv: ["daemon", "agent", "world", "hub"].index(_role(kv[0])),
    )
    stopped = []
    for name, part in order:
        pid = part.get("pid")
        if pid and pid_alive(pid) and _ours(pid) and _signal(pid, signal.SIGTERM):
            _wait_exit(pid, 30.0)
            stopped.append(name)
    return stopped


def _ours(pid: int) -> bool:
    """Whether ``pid`` is still a ``fleet`` process (not a recycled pid)."""
    try:
        return b"controller.cli" in open(f"/proc/{pid}/cmdline", "rb").read()
    except OSError:
        return False


def _role(name: str) -> str:
    return name if name in ("daemon", "world", "hub") else "agent"


def _signal(pid: int, sig: int = signal.SIGINT) -> bool:
    """``sig`` to ``pid`` (SIGINT to the lab's supervisor: it stops robots first); False when
    it had ended."""
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        return False
    return True
