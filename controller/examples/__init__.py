"""The example configs shipped with the package, the files ``fleet init`` writes.

Each kind is a commented TOML file in this package (package data, read with
``importlib.resources``, so an installed wheel has them too): ``dry-run`` is the repository's
top-level ``fleet.toml`` (this package's ``fleet.toml`` is the source; a test keeps the two
identical), ``rehearsal`` the top-level ``lab.toml`` (likewise). Every one passes ``fleet check``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources


@dataclass(frozen=True)
class Example:
    """One kind of example: its file in this package, the file ``fleet init`` writes by
    default, a line for ``fleet init --list``, and the commands to run next (``{config}``
    stands for the file written)."""

    kind: str
    file: str
    out: str
    summary: str
    next: tuple[str, ...]


_LAB_NEXT = (
    "fleet up --config {config}",
    "fleet resume --config {config}",  # a fresh lab starts with the e-stop engaged
)

CATALOG: tuple[Example, ...] = (
    Example(
        "dry-run",
        "fleet.toml",
        "fleet.toml",
        "the dry run on this machine: six sim robots capture a crate and carry it",
        ("fleet run --config {config}",),
    ),
    Example(
        "rehearsal",
        "rehearsal.toml",
        "lab.toml",
        "the lab rehearsed on one machine: hub, world, controller, an agent per sim robot",
        _LAB_NEXT,
    ),
    Example(
        "mavlink",
        "mavlink.toml",
        "lab.toml",
        "MAVLink robots (PX4, ArduRover) over UDP; rehearse with fleet world --mavlink",
        _LAB_NEXT,
    ),
    Example(
        "ros2",
        "ros2.toml",
        "lab.toml",
        "ROS 2 robots over rmw_zenoh; rehearse with fleet world --ros2",
        _LAB_NEXT,
    ),
    Example(
        "mixed",
        "mixed.toml",
        "lab.toml",
        "sim robots, a PX4, an ArduRover and ROS 2 robots in one fleet",
        _LAB_NEXT,
    ),
)
KINDS: tuple[str, ...] = tuple(e.kind for e in CATALOG)
DEFAULT_KIND = "dry-run"


def example(kind: str) -> Example:
    """The example ``kind`` (KeyError naming the valid kinds)."""
    for e in CATALOG:
        if e.kind == kind:
            return e
    raise KeyError(f"unknown example {kind!r}; expected one of {', '.join(KINDS)}")


def example_text(kind: str) -> str:
    """The example file of ``kind``, as shipped (read through importlib.resources)."""
    return resources.files(__name__).joinpath(example(kind).file).read_text(encoding="utf-8")


def next_lines(ex: Example, out: str) -> list[str]:
    """The commands to run next with the config ``out`` written (quoted for a shell)."""
    import shlex

    config = shlex.quote(str(out))
    return [
        f"{'next' if i == 0 else 'then'}: {cmd.format(config=config)}"
        for i, cmd in enumerate(ex.next)
    ]
