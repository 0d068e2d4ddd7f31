"""Two Linux network namespaces joined by a veth pair, for tests across a network boundary.

Only the namespaces, the veth pair and the /30 made here are touched: a test creates them
itself (needs root or CAP_NET_ADMIN) and deletes them in a ``finally``. Deleting a namespace
destroys the veth end inside it, and with it the pair.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from tests.support.config import ROOT


class NetnsUnavailable(RuntimeError):
    """The kernel or the user refused a namespace (not root, no CAP_NET_ADMIN, no ``ip``)."""


def ip(*args: str, ns: str | None = None, check: bool = True) -> subprocess.CompletedProcess:
    """``ip ARGS`` (inside namespace ``ns`` when given)."""
    cmd = ["ip", "netns", "exec", ns, "ip", *args] if ns else ["ip", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=10)
    if check and proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()}")
    return proc


@dataclass
class NetnsPair:
    """Namespaces ``a`` and ``b``; ``veth_a`` (address ``addr_a``) lives in ``a``, ``veth_b``
    (``addr_b``) in ``b``, both in the private /30 ``10.199.<subnet>.0/30``."""

    a: str
    b: str
    veth_a: str
    veth_b: str
    addr_a: str
    addr_b: str
    created: tuple[str, ...] = ()

    @classmethod
    def create(cls, tag: str, subnet: int) -> NetnsPair:
        """Create both namespaces and the link; NetnsUnavailable when the kernel refuses the
        first namespace (the caller skips), RuntimeError for any later failure (after undoing
        what was made)."""
        if shutil.which("ip") is None:
            raise NetnsUnavailable("no `ip` command (iproute2) on this machine")
        base = 4 * (subnet % 64)  # a /30 of its own: .base+1 and .base+2
        third = 100 + subnet // 64 % 100
        pair = cls(
            a=f"fleet-{tag}-a",
            b=f"fleet-{tag}-b",
            veth_a=f"fl{tag}a"[:15],
            veth_b=f"fl{tag}b"[:15],
            addr_a=f"10.199.{third}.{base + 1}",
            addr_b=f"10.199.{third}.{base + 2}",
        )
        first = ip("netns", "add", pair.a, check=False)
        if first.returncode != 0:
            raise NetnsUnavailable(
                f"`ip netns add {pair.a}` refused (exit {first.returncode}, uid {os.geteuid()}): "
                f"{first.stderr.strip() or 'no message'}"
            )
        pair.created = (pair.a,)
        try:
            ip("netns", "add", pair.b)
            pair.created = (pair.a, pair.b)
            # created inside namespace a, one end moved to b: nothing appears in the caller's
            ip("link", "add", pair.veth_a, "type", "veth", "peer", "name", pair.veth_b, ns=pair.a)
            ip("link", "set", pair.veth_b, "netns", pair.b, ns=pair.a)
            for ns, dev, addr in (
                (pair.a, pair.veth_a, pair.addr_a),
                (pair.b, pair.veth_b, pair.addr_b),
            ):
                ip("addr", "add", f"{addr}/30", "dev", dev, ns=ns)
                ip("link", "set", dev, "up", ns=ns)
                ip("link", "set", "lo", "up", ns=ns)  # traffic to the own address runs on lo
        except Exception:
            pair.delete()
            raise
        return pair

    def set_link(self, up: bool, side: str = "b") -> None:
        """Take one end of the link down (or up again) inside its namespace."""
        ns, dev = (self.a, self.veth_a) if side == "a" else (self.b, self.veth_b)
        ip("link", "set", dev, "up" if up else "down", ns=ns)

    def command(self, ns: str, *argv: str) -> list[str]:
        """``argv`` run inside namespace ``ns``."""
        return ["ip", "netns", "exec", ns, *argv]

    def delete(self) -> list[str]:
        """Delete the namespaces made (idempotent); returns the errors, if any."""
        errors = []
        for ns in self.created:
            proc = ip("netns", "del", ns, check=False)
            if proc.returncode != 0 and ns in ip("netns", "list", check=False).stdout.split():
                errors.append(f"ip netns del {ns}: {proc.stderr.strip()}")
        self.created = ()
        return errors


def fleet_argv(*args: str) -> list[str]:
    """The ``fleet`` command line this interpreter runs (for ``ip netns exec``)."""
    import sys

    return [sys.executable, "-m", "controller.cli", *args]


def spawn_in(pair: NetnsPair, ns: str, log_path: Path, *args: str) -> subprocess.Popen:
    """A ``fleet`` process inside namespace ``ns``, writing to a file (``ip netns exec`` execs
    the command: the process id is the fleet process's own)."""
    return spawn_argv_in(pair, ns, log_path, fleet_argv(*args))


def spawn_argv_in(pair: NetnsPair, ns: str, log_path: Path, argv: list[str]) -> subprocess.Popen:
    """Any command of this interpreter's (``argv``) inside namespace ``ns``, writing to a file."""
    with open(log_path, "w") as out:
        proc = subprocess.Popen(
            pair.command(ns, *argv),
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
            stdout=out,
            stderr=out,
        )
    proc.log_path = log_path  # type: ignore[attr-defined]
    return proc


def fleet_in(
    pair: NetnsPair, ns: str, *args: str, timeout: float = 30
) -> subprocess.CompletedProcess:
    """Run one ``fleet`` command inside namespace ``ns`` to its end."""
    return subprocess.run(
        pair.command(ns, *fleet_argv(*args)),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
