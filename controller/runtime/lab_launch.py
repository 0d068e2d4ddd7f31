"""``fleet up`` and ``fleet down`` on the command line: the checks before a lab starts, the
lab in the foreground (its console, its keys) or detached, and the stop of a detached lab
(``controller.runtime.lab`` is the supervisor itself)."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

from controller.commands import config_path, stop_on_signals

# agents per process (bench/lab.py, 15 s of a held rehearsal, load 5-10): a process each cost
# 120 MB and 4.4 % of a core per robot at 6 robots (724 MB, 26 %; one process for all six:
# 125 MB, 18 %), at 20 robots 2.4 GB and 62 % against 136 MB and 41 %, and bring-up took 41 s
# against 10 s. A process per robot keeps a crash to one robot (a lost robot is re-planned
# around; a group's crash loses its robots together), as on robots with their own computers:
# kept where it is cheap, up to ISOLATE_UP_TO robots; beyond, groups of GROUP agents.
ISOLATE_UP_TO = 8
GROUP = 10


DETACH_WAIT = 600.0  # s: --detach waits at most this long for the lab to be up


def agents_per_process(n_robots: int, given: int | None) -> int:
    """``--agents-per-process``, or by the fleet's size (above)."""
    if given:
        return given
    return 1 if n_robots <= ISOLATE_UP_TO else GROUP


def check_lab_config(cfg, mavlink: str | None, ros2: str | None) -> None:
    """Refuse (ConfigError, exit 2) what the lab cannot run: ``sim`` robots without a shared
    world; the ids of ``--mavlink``/``--ros2`` are checked as ``fleet world`` checks them."""
    from controller.config import ConfigError
    from controller.runtime.world import emulated_vehicles, ros2_bodies

    if any(r.spec.world_body for r in cfg.robots) and cfg.sim.world != "process":
        raise ConfigError(
            cfg.source,
            "sim.world",
            f"{cfg.sim.world!r}: fleet up runs one stand-in world shared by the sim robots; set "
            'sim.world = "process" (fleet init rehearsal writes such a config)',
        )
    emulated_vehicles(cfg, mavlink)
    ros2_bodies(cfg, ros2)


def remote_ids(cfg, text: str) -> tuple[str, ...]:
    """The ids of ``--remote`` (ConfigError naming one that is not a robot of the config)."""
    from controller.config import ConfigError

    ids = tuple(w.strip() for w in text.split(",") if w.strip())
    for rid in ids:
        if rid not in cfg.robot_ids:
            raise ConfigError(cfg.source, "robots", f"--remote {rid!r}: ids: {cfg.robot_ids}")
    return ids


def running_lab(cfg) -> dict | None:
    """The state of a lab of this fleet whose supervisor still runs, else None."""
    from controller.runtime.lab import pid_alive, read_state, state_path

    state = read_state(state_path(cfg))
    if state and state.get("stage") != "ended" and pid_alive(int(state.get("pid", 0))):
        return state
    return None


def _foreground(args, cfg, run_dir: Path) -> int:
    from controller.runtime.console import Keys, make_console
    from controller.runtime.lab import Lab, plan_parts, state_path
    from controller.runtime.lab_outcome import lab_outcome, print_outcome

    stop = stop_on_signals()
    parts = plan_parts(
        cfg,
        args.config,
        run_dir,
        args.mission,
        args.mavlink,
        args.ros2,
        args.ready_timeout,
        remote=remote_ids(cfg, args.remote),
        viz=args.viz,
        agents_per_process=agents_per_process(len(cfg.robots), args.agents_per_process),
    )
    tty = sys.stdout.isatty() and not args.plain and not args.json
    console = make_console(args.config, live=tty)
    lab = Lab(cfg, parts, run_dir, stop, console, args.ready_timeout, state_file=state_path(cfg))
    keys = None
    if tty and sys.stdin.isatty():

        def on_key(ch: str) -> None:
            if ch == "r":
                lab.command("resume")
            elif ch == "e":
                lab.command("estop")
            elif ch == "q":
                stop.set()

        keys = Keys(on_key)
    print(
        f"fleet up: fleet {cfg.fleet.name!r}, {len(parts)} processes; logs in {run_dir}",
        flush=True,
    )
    try:
        code = lab.run()
    finally:
        if keys is not None:
            keys.close()
        console.close()
    outcome = lab_outcome(lab, code, interrupted=stop.is_set())
    lab.save(verdict=outcome["verdict"], exit=outcome["exit"], outcome=outcome)
    print_outcome(outcome, as_json=args.json)
    return outcome["exit"]


def _detach(args, cfg, run_dir: Path) -> int:
    """Start the lab as a process of its own (its console in ``run_dir/console.log``) and
    return once it is up (its state file says so), or when it failed to come up."""
    import subprocess

    from controller.runtime.lab import read_state, state_path

    argv = [a for a in sys.argv[1:] if a != "--detach"]
    if not argv or argv[0] != "up":  # called in-process (tests): rebuild the command line
        argv = ["up", "--config", args.config, "--mission", args.mission]
        argv += ["--ready-timeout", f"{args.ready_timeout:g}"]
        argv += (["--mavlink", args.mavlink] if args.mavlink else []) + (
            ["--ros2", args.ros2] if args.ros2 else []
        )
        argv += (["--remote", args.remote] if args.remote else []) + (["--viz"] if args.viz else [])
        if args.agents_per_process:
            argv += ["--agents-per-process", str(args.agents_per_process)]
    argv += ["--plain", "--run-dir", str(run_dir)]
    with open(run_dir / "console.log", "w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "controller.cli", *argv],
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
    path = state_path(cfg)
    deadline = time.monotonic() + DETACH_WAIT
    while time.monotonic() < deadline:
        state = read_state(path) or {}
        mine = state.get("pid") == proc.pid
        if proc.poll() is not None or (mine and state.get("stage") in ("waiting", "running")):
            break
        time.sleep(0.2)  # polling the lab's own state file for its stage (a handshake)
    state = read_state(path) or {}
    if proc.poll() is not None or state.get("pid") != proc.pid:
        tail = (run_dir / "console.log").read_text(errors="replace")[-1500:]
        print(f"fleet up: the lab did not come up:\n{tail}", file=sys.stderr)
        return 1
    print(
        f"fleet up: lab of fleet {cfg.fleet.name!r} up in {state.get('ready_s') or 0:.0f} s "
        f"(pid {proc.pid}; logs in {run_dir}).\n"
        f"  It is stopped until an operator's resume: fleet resume --config {args.config}\n"
        f"  Watch it: fleet status --config {args.config}  (or {run_dir / 'console.log'})\n"
        f"  Stop it:  fleet down --config {args.config}  (--wait: after the job's end)"
    )
    return 0


def _wait_exit(pid: int, timeout: float) -> bool:
    """Whether the process ``pid`` ended within ``timeout`` s (0: no limit)."""
    from controller.runtime.lab import pid_alive

    deadline = time.monotonic() + timeout if timeout > 0 else None
    while pid_alive(pid):
        if deadline is not None and time.monotonic() > deadline:
            return False
        time.sleep(0.2)  # polling the supervisor's process for its exit (it is not our child)
    return True


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


def up(args) -> int:
    """``fleet up``: see controller/commands/up.py."""
    from controller.config import load_config
    from controller.runtime.lab import new_run_dir

    cfg = load_config(config_path(args))
    check_lab_config(cfg, args.mavlink, args.ros2)
    remote_ids(cfg, args.remote)
    other = running_lab(cfg)
    if other is not None:
        print(
            f"fleet up: a lab of fleet {cfg.fleet.name!r} runs already (pid {other['pid']}, "
            f"{other['run_dir']}): fleet down --config {args.config}",
            file=sys.stderr,
        )
        return 1
    run_dir = Path(args.run_dir) if args.run_dir else new_run_dir(cfg)
    run_dir.mkdir(parents=True, exist_ok=True)
    run_dir = run_dir.resolve()
    if args.detach:
        return _detach(args, cfg, run_dir)
    return _foreground(args, cfg, run_dir)


def down(args) -> int:
    """``fleet down``: see controller/commands/down.py."""
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
