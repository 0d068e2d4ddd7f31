"""No import circle in the ``controller`` package (issue 21 item 7).

A stdlib ``ast`` walk, no new dependency: every import statement of every module (those inside
functions too: a lazy import is still a dependency; not those under ``if TYPE_CHECKING:``, which
never run), resolved to the module it names, then Tarjan's strongly connected components. A
submodule is not taken to import its parent package (Python runs the parent's ``__init__`` first,
but that is the package's structure, not a dependency of the submodule). grimp/import-linter
would do the same walk; one function here keeps the test readable and the venv unchanged.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.support.config import ROOT
from tests.support.imports import type_checking_blocks


def module_names(package: Path) -> dict[str, Path]:
    """Dotted module name -> file for every module under ``package`` (its parent on sys.path)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The module of ours that ``name`` (a module or a module's attribute) lives in."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(package: Path) -> dict[str, set[str]]:
    """Module -> the modules of ``package`` it imports (run-time imports, anywhere in it)."""
    modules = module_names(package)
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for mod, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        skip = type_checking_blocks(tree)
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: from the module's package, up level - 1
                    pkg = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    pkg = pkg[: len(pkg) - (node.level - 1)]
                    base = ".".join(pkg + ([base] if base else []))
                names = [f"{base}.{a.name}" for a in node.names] or [base]
            for n in names:
                target = _resolve(n, modules)
                if target and target != mod:
                    graph[mod].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                scc = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    scc.append(m)
                    if m == node:
                        break
                if len(scc) > 1:
                    out.append(sorted(scc))
    return out


def test_controller_has_no_import_circle():
    graph = import_graph(ROOT / "controller")
    assert "controller.config.validate" in graph  # the walk sees the package's modules
    assert "controller.config.security" in graph["controller.config.validate"]
    assert cycles(graph) == []


def test_config_package_layers():
    """load <- driver_sections <- sections <- acl, security <- validate <- __init__; nothing in
    the package imports the package itself (that would be a circle through __init__)."""
    graph = import_graph(ROOT / "controller")
    order = ["load", "driver_sections", "sections", "acl", "security", "validate"]
    for i, name in enumerate(order):
        ours = {m for m in graph[f"controller.config.{name}"] if m.startswith("controller.config")}
        later = {f"controller.config.{n}" for n in order[i + 1 :]} | {"controller.config"}
        assert not ours & later, (name, ours & later)


def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root / "pkg"


@pytest.mark.parametrize(
    ("files", "cycle"),
    [
        (  # the old controller/acl.py <-> controller/config.py, lazily inside functions
            {
                "pkg/__init__.py": "",
                "pkg/config.py": "def f():\n    from pkg.acl import acl_for\n",
                "pkg/acl.py": "def main():\n    from pkg.config import load\n",
            },
            ["pkg.acl", "pkg.config"],
        ),
        (  # relative imports, through a package's __init__
            {
                "pkg/__init__.py": "",
                "pkg/sub/__init__.py": "from .a import x\n",
                "pkg/sub/a.py": "from pkg import b\n",
                "pkg/b.py": "from . import sub\n",
            },
            ["pkg.b", "pkg.sub", "pkg.sub.a"],
        ),
    ],
)
def test_the_walk_finds_a_circle(tmp_path, files, cycle):
    assert cycles(import_graph(_write(tmp_path, files))) == [cycle]


def test_type_checking_imports_are_no_circle(tmp_path):
    pkg = _write(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg import b\n",
            "pkg/b.py": (
                "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import a\n"
            ),
        },
    )
    assert cycles(import_graph(pkg)) == []
