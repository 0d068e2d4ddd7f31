"""Validation of scene messages against the published Foxglove JSON Schemas (vendored in
``controller/scene/schemas``), as published and in a strict copy that also refuses fields the
schema does not name (a misspelt field is silently ignored by Foxglove: the entity just does not
show)."""

from __future__ import annotations

import copy
from functools import cache
from typing import Any

import jsonschema

from controller.scene.builder import schema


def _strict(node: Any) -> Any:
    if isinstance(node, dict):
        out = {k: _strict(v) for k, v in node.items()}
        if "properties" in out and out.get("type") == "object":
            out.setdefault("additionalProperties", False)
        return out
    if isinstance(node, list):
        return [_strict(v) for v in node]
    return node


@cache
def validators(name: str) -> tuple[jsonschema.Validator, jsonschema.Validator]:
    s = schema(name)
    cls = jsonschema.validators.validator_for(s, default=jsonschema.Draft202012Validator)
    cls.check_schema(s)
    return cls(s), cls(_strict(copy.deepcopy(s)))


def errors(name: str, data: Any) -> list[str]:
    """What is wrong with ``data`` as a ``name`` message (empty: valid, strictly too)."""
    out = []
    for v in validators(name):
        out += [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in v.iter_errors(data)]
    return out
