"""Layering: the planning/estimation core does no I/O, and the packages keep their seams.

- controller modules outside the I/O edge (bus, recorder, replay, runtime, cli, commands) must
  not import zenoh, pybullet, pymavlink or mcap, nor read the wall clock (``time``, ``datetime``);
- controller/ imports drivers/ or sim_backend/ only in the composition root (controller/runtime.py);
- drivers/ imports nothing of controller/ but the wire contract (controller.wire);
- sim_backend/ knows nothing of the bus (no zenoh, no controller.bus or controller.wire).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import ROOT

IO_LIBS = {"zenoh", "pybullet", "pybullet_data", "pymavlink", "mcap"}
CLOCK_LIBS = {"time", "datetime"}
EDGE = {"bus", "recorder", "replay", "runtime", "cli", "ratekeeper"}
COMPOSITION_ROOT = {"runtime"}


def _type_checking_blocks(tree: ast.AST) -> set[int]:
    """ids of nodes inside ``if TYPE_CHECKING:`` (type-only imports are no runtime coupling)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                skip.update(id(n) for n in ast.walk(child))
    return skip


def imports_of(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    skip = _type_checking_blocks(tree)
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def top(names: set[str]) -> set[str]:
    return {n.split(".")[0] for n in names}


def modules(pkg: str) -> list[Path]:
    return sorted((ROOT / pkg).rglob("*.py"))


def is_edge(path: Path) -> bool:
    rel = path.relative_to(ROOT / "controller")
    return rel.parts[0] == "commands" or path.stem in EDGE


CORE = [p for p in modules("controller") if not is_edge(p)]


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(ROOT)))
def test_core_modules_do_no_io_and_read_no_clock(path):
    bad = top(imports_of(path)) & (IO_LIBS | CLOCK_LIBS)
    assert not bad, f"{path.name} imports {sorted(bad)}: the planning core must stay pure"


@pytest.mark.parametrize("path", modules("controller"), ids=lambda p: str(p.relative_to(ROOT)))
def test_controller_does_not_import_robot_side(path):
    if path.stem in COMPOSITION_ROOT and path.parent.name == "controller":
        return
    bad = top(imports_of(path)) & {"drivers", "sim_backend"}
    assert not bad, f"{path.name} imports {sorted(bad)} outside the composition root"


@pytest.mark.parametrize("path", modules("drivers"), ids=lambda p: str(p.relative_to(ROOT)))
def test_drivers_import_only_the_wire_contract(path):
    ours = {n for n in imports_of(path) if n.split(".")[0] == "controller"}
    allowed = {"controller", "controller.wire"} | {
        n for n in ours if n.startswith("controller.wire.")
    }
    assert ours <= allowed, f"{path.name} imports {sorted(ours - allowed)} of controller/"


@pytest.mark.parametrize("path", modules("sim_backend"), ids=lambda p: str(p.relative_to(ROOT)))
def test_sim_backend_knows_nothing_of_the_bus(path):
    names = imports_of(path)
    assert "zenoh" not in top(names)
    assert not any(n.startswith(("controller.bus", "controller.wire")) for n in names)


def test_the_checker_catches_a_violation(tmp_path):
    bad = tmp_path / "planner.py"
    bad.write_text("import numpy as np\nfrom zenoh import Config\nimport time\n")
    assert top(imports_of(bad)) & IO_LIBS == {"zenoh"}
    assert top(imports_of(bad)) & CLOCK_LIBS == {"time"}
