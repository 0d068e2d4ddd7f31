"""Import-graph helpers shared by the layering and the import-circle tests."""

from __future__ import annotations

import ast


def type_checking_blocks(tree: ast.AST) -> set[int]:
    """ids of nodes inside ``if TYPE_CHECKING:`` (type-only imports are no runtime coupling)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                skip.update(id(n) for n in ast.walk(child))
    return skip
