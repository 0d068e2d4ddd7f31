"""``fleet up [--config F] [--mission M] [--mavlink [IDS]] [--ros2 [IDS]] [--detach]``: the
whole lab from one config, in one command.

Brings up the hub, the stand-in world when rehearsing (any ``sim`` robot, or MAVLink/ROS 2
robots emulated with ``--mavlink``/``--ros2``; none when every robot is real), one agent per
robot and the controller, in that order, each once the one before is seen ready on the bus, each
with its own log file in the run's folder (``<log.dir>/<fleet>-lab-<time>/``, beside the
daemon's MCAP). A crashed agent or hub is restarted with back-off; a restart never lifts an
e-stop. A fresh lab is stopped until an operator's resume (``fleet resume``, or r in the
console); in a rehearsal the object holds its start until then (``sim.object_start``). The
console shows every robot, the job's phase and what to do next; keys r resume, e e-stop, q stop.
The lab ends with the job (a verdict line, the figures, the next step), or on Ctrl-C: the e-stop
first (every robot stopped), then every process, the MCAP whole. ``--detach`` returns once the
lab is up; ``fleet down`` stops it (``--wait``: after the job's end). Exit 0 when the job did
what the config asks, 1 when it failed or was stopped, 2 on a bad config.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from controller.commands import (
    add_config_argument,
    add_emulation_arguments,
    config_path,
    stop_on_signals,
)
from controller.config import MISSION_KINDS

EXAMPLES = """examples:
  fleet init rehearsal --out lab.toml          # a rehearsal config: six sim robots, one world
  fleet up --config lab.toml                    # bring the lab up; r resumes, Ctrl-C stops
  fleet up --config lab.toml --detach           # in the background; then:
  fleet resume --config lab.toml                #   the operator's go: the job starts
  fleet down --config lab.toml --wait           #   the job's verdict, then everything stops
  fleet up --config mixed.toml --mavlink r3 --ros2 r5   # emulate r3 (MAVLink) and r5 (ROS 2)
"""

# agents per process (bench/lab.py, 15 s of a held rehearsal, load 5-10): a process each cost
# 120 MB and 4.4 % of a core per robot at 6 robots (724 MB, 26 %; one process for all six:
# 125 MB, 18 %), at 20 robots 2.4 GB and 62 % against 136 MB and 41 %, and bring-up took 41 s
# against 10 s. A process per robot keeps a crash to one robot (a lost robot is re-planned
# around; a group's crash loses its robots together), as on robots with their own computers:
# kept where it is cheap, up to ISOLATE_UP_TO robots; beyond, groups of GROUP agents.
ISOLATE_UP_TO = 8
GROUP = 10


def agents_per_process(n_robots: int, given: int | None) -> int:
    """``--agents-per-process``, or by the fleet's size (above)."""
    if given:
        return given
    return 1 if n_robots <= ISOLATE_UP_TO else GROUP


DETACH_WAIT = 600.0  # s: --detach waits at most this long for the lab to be up


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument(
        "--mission",
        choices=MISSION_KINDS,
        default="capture",
        help="the daemon's mission (capture: the whole job; hold: every robot still)",
    )
    add_emulation_arguments(parser)
    parser.add_argument(
        "--remote",
        default="",
        metavar="IDS",
        help="robots whose agents run on their own computers (fleet driver ID there): not "
        "started here, waited for on the bus all the same (comma-separated ids)",
    )
    parser.add_argument(
        "--agents-per-process",
        type=int,
        default=None,
        metavar="N",
        help="robot agents run N to a process, a thread each (default: a process per robot up "
        f"to {ISOLATE_UP_TO} robots, beyond that {GROUP} to a process; bench/lab.py measures "
        "both)",
    )
    parser.add_argument(
        "--viz",
        action="store_true",
        help="the daemon serves the fleet live to Foxglove on ws://127.0.0.1:<viz.port>",
    )
    parser.add_argument(
        "--detach",
        action="store_true",
        help="return once the lab is up (it runs on; fleet down stops it)",
    )
    parser.add_argument(
        "--ready-timeout",
        type=float,
        default=180.0,
        help="seconds each part may take to be ready (a loaded machine is slow; default 180)",
    )
    parser.add_argument(
        "--plain", action="store_true", help="plain lines even on a terminal (no live panel)"
    )
    parser.add_argument("--json", action="store_true", help="end with one JSON object on stdout")
    parser.add_argument("--run-dir", help=argparse.SUPPRESS, default=None)  # --detach's child


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


def run(args) -> int:
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
