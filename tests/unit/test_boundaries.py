"""Layering, checked by folder (docs/architecture.md, "Packages and their seams").

- ``controller/planning``, ``controller/estimation``, ``controller/mission`` are pure: besides the
  standard library (no clock, threads, sockets, processes or global randomness) they import only
  numpy, scipy, osqp, filterpy, shapely, each other, and ``controller.config``,
  ``controller.geometry``, ``controller.wire`` and its typed events (``controller.events``);
- ``controller/io`` is the only importer of zenoh, mcap and foxglove (the live view's SDK);
  ``controller/viz.py`` the only importer of matplotlib;
- ``controller/runtime`` is the only part of ``controller/`` that imports ``drivers`` or
  ``sim_backend``;
- ``drivers/`` imports nothing of ``controller/`` but the wire contract (``controller.wire``)
  and the e-stop latch built on it (``controller.latch``: the one latch of every holder, agents
  included), which in turn imports only ``controller.wire`` and the standard library, no clock;
- ``sim_backend/`` knows nothing of the bus (no zenoh, no ``controller.io`` or
  ``controller.wire``) and nothing of the drivers, with one listed exception: the MAVLink
  vehicle emulator shares the NED conversions of ``drivers/mavlink/convert.py``;
- ``controller/commands`` modules parse and delegate: they define ``add_arguments`` and ``run``
  and nothing else;
- ``controller/scene`` is pure too (the Foxglove scene from messages): the standard library
  without a clock, numpy, and ``controller.config``/``geometry``/``wire``/``events``;
- ``controller/replay`` reads what the runtime wrote: only the commands, the plots
  (``controller/viz.py``) and the lab's verdict (``runtime/lab_outcome.py``) import it, never the
  planning core, the bus or the drivers; its metrics are pure (numpy and ``geometry``);
- the tests share helpers only through ``tests/support`` (no test module imports another).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.support.config import ROOT
from tests.support.imports import type_checking_blocks

PURE_FOLDERS = ("planning", "estimation", "mission")
PURE_THIRD_PARTY = {"numpy", "scipy", "osqp", "filterpy", "shapely"}
PURE_OURS = ("controller.config", "controller.events", "controller.geometry", "controller.wire")
FORBIDDEN_STDLIB = {
    "time",
    "datetime",
    "threading",
    "multiprocessing",
    "socket",
    "subprocess",
    "asyncio",
    "random",
    "signal",
    "select",
}
# sim_backend → drivers: the one listed exception (the emulator shares the NED conversions)
SIM_BACKEND_MAY_IMPORT = {
    "sim_backend/mavlink_vehicle.py": {"drivers.mavlink.convert", "drivers.mavlink"},
}


def imports_of(path: Path) -> set[str]:
    """Every module a file imports at run time (``from a import b`` gives ``a`` and ``a.b``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    skip = type_checking_blocks(tree)
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


def files(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def pure_violations(path: Path) -> list[str]:
    """Imports of a pure-core module that break the rule."""
    import sys

    bad = []
    for name in sorted(imports_of(path)):
        root = name.split(".")[0]
        if root == "controller":
            ok = name == "controller" or name.startswith(
                tuple(f"controller.{f}" for f in PURE_FOLDERS) + PURE_OURS
            )
            # ``from controller import geometry`` gives controller.geometry: covered above
            if not ok:
                bad.append(name)
        elif root in FORBIDDEN_STDLIB:
            bad.append(name)
        elif root in sys.stdlib_module_names or root == "__future__":
            continue
        elif root not in PURE_THIRD_PARTY:
            bad.append(name)
    return bad


PURE = [p for f in PURE_FOLDERS for p in files(f"controller/{f}")]


@pytest.mark.parametrize("path", PURE, ids=rel)
def test_pure_core_imports_only_the_allowed(path):
    bad = pure_violations(path)
    assert not bad, f"{rel(path)} imports {bad}: the planning core must stay pure"


@pytest.mark.parametrize("path", files("controller"), ids=rel)
def test_only_io_imports_zenoh_and_mcap(path):
    if rel(path).startswith("controller/io/"):
        return
    bad = top(imports_of(path)) & {"zenoh", "mcap", "foxglove"}
    assert not bad, f"{rel(path)} imports {sorted(bad)}: only controller/io/ may"


@pytest.mark.parametrize("path", files("controller"), ids=rel)
def test_only_viz_imports_matplotlib(path):
    if rel(path) == "controller/viz.py":
        return
    assert "matplotlib" not in top(imports_of(path)), f"{rel(path)} imports matplotlib"


@pytest.mark.parametrize("path", files("controller"), ids=rel)
def test_only_runtime_imports_the_robot_side(path):
    if rel(path).startswith("controller/runtime/"):
        return
    bad = top(imports_of(path)) & {"drivers", "sim_backend"}
    assert not bad, f"{rel(path)} imports {sorted(bad)} outside controller/runtime/"


# what drivers/ may import of controller/: the wire contract and the e-stop latch on it
DRIVERS_MAY_IMPORT = ("controller.wire", "controller.latch")


@pytest.mark.parametrize("path", files("drivers"), ids=rel)
def test_drivers_import_only_the_wire_contract(path):
    ours = {n for n in imports_of(path) if n.split(".")[0] == "controller"}
    allowed = {"controller", *DRIVERS_MAY_IMPORT} | {
        n for n in ours if n.startswith(tuple(f"{m}." for m in DRIVERS_MAY_IMPORT))
    }
    assert ours <= allowed, f"{rel(path)} imports {sorted(ours - allowed)} of controller/"


def test_the_latch_imports_only_the_wire_contract_and_no_clock():
    path = ROOT / "controller" / "latch.py"
    names = imports_of(path)
    ours = {n for n in names if n.split(".")[0] == "controller"}
    assert ours <= {"controller", "controller.wire"}, sorted(ours)
    assert not top(names) & (FORBIDDEN_STDLIB - {"threading"}), sorted(names)
    assert not top(names) & {"zenoh", "numpy"}


@pytest.mark.parametrize("path", files("sim_backend"), ids=rel)
def test_sim_backend_knows_nothing_of_the_bus_or_drivers(path):
    names = imports_of(path)
    assert "zenoh" not in top(names)
    assert not any(n.startswith(("controller.io", "controller.wire")) for n in names)
    drivers = {n for n in names if n.split(".")[0] == "drivers"}
    allowed = SIM_BACKEND_MAY_IMPORT.get(rel(path), set())
    extra = {n for n in drivers if not any(n == a or n.startswith(a + ".") for a in allowed)}
    assert not extra, f"{rel(path)} imports {sorted(extra)} of drivers/"


@pytest.mark.parametrize(
    "path", [p for p in files("controller/commands") if p.name != "__init__.py"], ids=rel
)
def test_commands_parse_and_delegate(path):
    tree = ast.parse(path.read_text())
    defs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef | ast.ClassDef)}
    assert defs <= {"add_arguments", "run"}, f"{rel(path)} defines {sorted(defs)}"


SCENE_OURS = ("controller.scene",) + PURE_OURS


@pytest.mark.parametrize("path", files("controller/scene"), ids=rel)
def test_the_scene_is_pure(path):
    import sys

    bad = []
    for name in sorted(imports_of(path)):
        root = name.split(".")[0]
        if root == "controller":
            if name != "controller" and not name.startswith(SCENE_OURS):
                bad.append(name)
        elif root in FORBIDDEN_STDLIB or (
            root not in sys.stdlib_module_names and root not in {"__future__", "numpy"}
        ):
            bad.append(name)
    assert not bad, f"{rel(path)} imports {bad}: the scene is built from messages alone"


# who may read the logs' analysis: the commands, the plots and the lab's verdict
REPLAY_READERS = ("controller/commands/", "controller/replay/", "controller/viz.py")
REPLAY_READERS_LISTED = {"controller/runtime/lab_outcome.py", "controller/docs.py"}


@pytest.mark.parametrize("path", files("controller"), ids=rel)
def test_replay_is_read_by_the_edges_only(path):
    r = rel(path)
    if r.startswith(REPLAY_READERS) or r in REPLAY_READERS_LISTED:
        return
    bad = {n for n in imports_of(path) if n.startswith("controller.replay")}
    assert not bad, f"{r} imports {sorted(bad)}: only the commands and the plots read logs"


def test_replay_metrics_are_pure():
    names = imports_of(ROOT / "controller" / "replay" / "metrics.py")
    ours = {n for n in names if n.split(".")[0] == "controller"}
    assert ours <= {"controller", "controller.geometry"}, sorted(ours)
    assert not top(names) & (FORBIDDEN_STDLIB | {"zenoh", "mcap"}), sorted(names)


NODE_PARTS = sorted((ROOT / "controller" / "runtime").glob("node*.py"))


def test_the_controller_node_is_split_by_job():
    """The node is its tick pipeline and status (``node.py``); its latch, inputs, outputs and
    stage timings are parts of their own (issue 35 item 5): each short, and no part imports the
    node (nor reads a clock: the node injects its own)."""
    names = {p.stem for p in NODE_PARTS}
    assert {"node", "node_latch", "node_inputs", "node_outputs", "node_times"} <= names
    for p in NODE_PARTS:
        assert len(p.read_text().splitlines()) <= 230, rel(p)
        if p.stem != "node":
            assert "controller.runtime.node" not in imports_of(p), rel(p)
            assert "time" not in top(imports_of(p)), rel(p)


def test_no_function_of_the_mission_layer_is_over_60_lines():
    """The mission's stages stay readable (issue 35): no function or method in
    ``controller/mission/`` over 60 lines."""
    long = []
    for path in files("controller/mission"):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > 60:
                    long.append(f"{rel(path)}:{node.lineno} {node.name} ({n} lines)")
    assert long == []


TEST_FILES = [p for p in files("tests") if "support" not in p.relative_to(ROOT / "tests").parts]


@pytest.mark.parametrize("path", TEST_FILES, ids=rel)
def test_tests_share_helpers_only_through_support(path):
    own = {n for n in imports_of(path) if n.split(".")[0] == "tests"}
    bad = {n for n in own if n != "tests" and not n.startswith(("tests.support",))}
    assert not bad, f"{rel(path)} imports {sorted(bad)}: move the shared helper to tests/support"


def test_the_checker_catches_violations(tmp_path):
    bad = tmp_path / "planner.py"
    bad.write_text(
        "import numpy as np\nfrom zenoh import Config\nimport time\n"
        "from controller.io.bus import Bus\nimport math\n"
    )
    assert pure_violations(bad) == [
        "controller.io.bus",
        "controller.io.bus.Bus",
        "time",
        "zenoh",
        "zenoh.Config",
    ]
