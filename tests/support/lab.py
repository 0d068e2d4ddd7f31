"""The lab as separate processes for the integration tests: ``fleet`` subprocesses writing to
log files, stopped (SIGCONT first, SIGTERM, then SIGKILL) in a ``finally``; lab configs on a free
loopback port; a test-side zenoh session to watch the e-stop latch."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from controller import wire
from tests.support.config import ROOT, base_config_dict, write_toml


def fleet(*args: str, timeout: float = 60, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """Run one ``fleet`` command to its end (in ``cwd``: the repository by default)."""
    return subprocess.run(
        [sys.executable, "-m", "controller.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )


def fleet_json(*args: str, timeout: float = 60) -> tuple[int, dict[str, Any]]:
    """Run a ``fleet ... --json`` command: (exit status, its JSON object)."""
    proc = fleet(*args, "--json", timeout=timeout)
    try:
        out = json.loads(proc.stdout)
    except json.JSONDecodeError as exc:
        raise AssertionError(f"no JSON from fleet {args}: {proc.stdout!r} {proc.stderr}") from exc
    return proc.returncode, out


def spawn(log_path: Path, *args: str) -> subprocess.Popen:
    """A fleet process writing to a file, so a chatty child never blocks on a full pipe."""
    with open(log_path, "w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "controller.cli", *args],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
            stdout=out,
            stderr=out,
        )
    proc.log_path = log_path  # type: ignore[attr-defined]
    return proc


def stop_all(procs: list[subprocess.Popen]) -> list[int]:
    """Stop every process (a SIGSTOPped one is continued first); kill what does not end."""
    codes = []
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGCONT)
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            codes.append(p.wait(timeout=20))
        except subprocess.TimeoutExpired:
            p.kill()  # never leave a process behind
            codes.append(p.wait())
    for p, code in zip(procs, codes, strict=True):  # shown by pytest when the test fails
        if getattr(p, "log_path", None) is not None:  # one of spawn's (others log elsewhere)
            print(f"--- {' '.join(map(str, p.args[-6:]))} (exit {code}) ---", file=sys.stderr)
            print(tail(p, 1500), file=sys.stderr)
    return codes


def release(cfg, *identity: str, timeout: float = 10.0) -> dict[str, Any]:
    """The operator's first ``fleet resume`` of a fresh lab: its processes start with the e-stop
    latch unknown, robots stopped, until an operator releases it. Returns its JSON."""
    proc = fleet("resume", "--config", str(cfg), "--timeout", str(timeout), *identity, "--json")
    out = json.loads(proc.stdout) if proc.stdout.strip() else {}
    # the exit status and stderr too: a resume can be confirmed and still exit non-zero
    assert proc.returncode == 0 and out.get("confirmed") is True, (
        proc.returncode,
        out,
        proc.stderr[-1500:],
    )
    return out


def tail(p: subprocess.Popen, n: int = 2000) -> str:
    return Path(p.log_path).read_text()[-n:]  # type: ignore[attr-defined]


def lab_config(
    tmp_path: Path,
    port: int,
    robots: int = 2,
    zenoh: dict[str, Any] | None = None,
    sections: dict[str, dict[str, Any]] | None = None,
    **fleet_keys: Any,
) -> Path:
    """The shipped config cut to ``robots`` robots, on the ideal backend, zenoh on ``port``
    (``zenoh``: more keys of that section; ``sections``: more sections, by name)."""
    cfg = base_config_dict()
    cfg["robots"] = cfg["robots"][:robots]
    cfg["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    cfg["zenoh"].update(zenoh or {})
    cfg["sim"]["backend"] = "ideal"
    cfg["log"] = {"dir": str(tmp_path / "runs")}
    cfg["fleet"].update(fleet_keys)
    cfg.update(sections or {})
    return write_toml(tmp_path / "lab.toml", cfg)


def latch_states(bus, timeout: float = 1.0) -> dict[str, wire.EStop]:
    """Every holder's latched e-stop, by ``role/id``."""
    out = {}
    for key, msg in bus.query_replies(bus.estop_wildcard(), wire.EStop, timeout):
        parsed = wire.parse_key(key, bus.fleet)
        if parsed is not None:
            out[f"{parsed.parts['role']}/{parsed.id}"] = msg
    return out


def status(cfg, timeout: float = 2.0) -> dict:
    """``fleet status --json`` of a running daemon ({"ok": False} when none answers)."""
    proc = fleet("status", "--config", str(cfg), "--json", "--timeout", str(timeout))
    return json.loads(proc.stdout) if proc.stdout.strip() else {"ok": False}


def connect_client(port: int, what: str, fleet_name: str = "lab"):
    """A test-side zenoh client of the endpoint on 127.0.0.1:``port``, retried until something
    listens there (the handshake: the hub, the world, a daemon)."""
    from controller.config import ZenohSection
    from controller.io.bus import Bus
    from tests.support.wait import wait_for

    box: list[Bus] = []

    def opened() -> bool:
        try:
            box.append(
                Bus(
                    ZenohSection(),
                    fleet_name,
                    mode="client",
                    listen=[],
                    connect=[f"tcp/127.0.0.1:{port}"],
                )
            )
        except Exception:  # noqa: BLE001 - not listening yet
            return False
        return True

    wait_for(opened, 20, f"{what} listening")
    return box[0]
