"""The config described by its own dataclasses: every key of fleet.toml with its type, default,
rules and the comment written beside it in the source (:func:`config_keys`), and the JSON Schema
of fleet.toml (:func:`json_schema`) that ``fleet schema`` writes and TOML editors (Taplo, Even
Better TOML) validate and complete with. One source for both: the reference page
(docs/reference/config.md, ``python -m controller.docs``) and the schema are made here.

The schema checks what one key can check alone (unknown keys, types, ranges, choices, patterns);
the rules between keys (a robot inside the room, identities, endpoints) stay ``fleet check``'s.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import io
import textwrap
import tokenize
import types
import typing
from dataclasses import dataclass
from typing import Any

#: the JSON Schema draft written (the one Taplo and Even Better TOML read)
DRAFT = "http://json-schema.org/draft-07/schema#"
#: the schema file beside a config, which its first line names (``#:schema ./fleet.schema.json``)
SCHEMA_FILE = "fleet.schema.json"
_NOT_KEYS = ("source", "notes")  # FleetConfig fields the loader fills, never TOML keys
_TOOL_COMMENTS = ("fmt:", "noqa", "type:", "pragma")


# --------------------------------------------------------------------------- source comments


@functools.cache
def _class_source(cls: type) -> tuple[ast.ClassDef, dict[int, tuple[str, bool]]] | None:
    """The class's syntax tree and its comments by line: (text, on a line of its own)."""
    try:
        src = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return None
    node = ast.parse(src).body[0]
    if not isinstance(node, ast.ClassDef):
        return None
    comments: dict[int, tuple[str, bool]] = {}
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.COMMENT:
            text = tok.string.lstrip("#").strip()
            if text.startswith(_TOOL_COMMENTS):
                continue
            comments[tok.start[0]] = (text, not tok.line[: tok.start[1]].strip())
    return node, comments


def class_doc(cls: type) -> str:
    """The class's own docstring (not the signature a dataclass makes up), or ''."""
    got = _class_source(cls)
    return (ast.get_docstring(got[0]) or "") if got else ""


def member_comments(cls: type) -> dict[str, str]:
    """Each field's (or enum member's) comment: the comment lines right above it and the one at
    the end of its line(s), joined."""
    got = _class_source(cls)
    if got is None:
        return {}
    node, comments = got
    out: dict[str, str] = {}
    for stmt in node.body:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            name = stmt.target.id
        elif (
            isinstance(stmt, ast.Assign)
            and len(stmt.targets) == 1
            and isinstance(stmt.targets[0], ast.Name)
        ):
            name = stmt.targets[0].id
        else:
            continue
        above: list[str] = []
        line = stmt.lineno - 1
        while line in comments and comments[line][1]:
            above.insert(0, comments[line][0])
            line -= 1
        end = stmt.end_lineno or stmt.lineno
        after = [
            comments[n][0]
            for n in range(stmt.lineno, end + 1)
            if n in comments and not comments[n][1]
        ]
        text = " ".join(above + after).strip()
        if text:
            out[name] = text
    return out


# --------------------------------------------------------------------------- the keys


@dataclass(frozen=True)
class Key:
    """One key of fleet.toml: its dotted path (``[]`` for an array of tables), TOML type,
    default (``required`` when it has none), rules and description."""

    path: str
    type: str
    default: str
    rules: str
    doc: str
    required: bool


@dataclass(frozen=True)
class Section:
    """A table of fleet.toml (``[fleet]``, ``[[robots]]``, ``[robots.mavlink]``, ...)."""

    header: str
    doc: str
    keys: tuple[Key, ...]


def _fields(cls: type) -> list[tuple[dataclasses.Field, Any]]:
    hints = typing.get_type_hints(cls)
    return [
        (f, hints[f.name])
        for f in dataclasses.fields(cls)
        if f.name not in _NOT_KEYS and not f.metadata.get("internal")
    ]


def _optional(tp: Any) -> Any:
    """``T`` of ``T | None`` (an optional key: present means T), else ``tp``."""
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(inner) == 1:
            return inner[0]
    return tp


def _table_of(tp: Any) -> tuple[type, bool] | None:
    """(dataclass, is an array of tables) when ``tp`` is a table key, else None."""
    tp = _optional(tp)
    if dataclasses.is_dataclass(tp):
        return tp, False  # type: ignore[return-value]
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple and len(args) == 2 and args[1] is Ellipsis:
        if dataclasses.is_dataclass(args[0]):
            return args[0], True
    return None


def type_name(tp: Any) -> str:
    """The TOML type of a field: ``number``, ``[number, number]``, ``array of string``..."""
    opt = _optional(tp)
    if opt is not tp:
        return type_name(opt)
    names = {float: "number", int: "integer", bool: "boolean", str: "string"}
    if tp in names:
        return names[tp]
    if dataclasses.is_dataclass(tp):
        return "table"
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {type_name(args[0])}"
        return "[" + ", ".join(type_name(a) for a in args) + "]"
    if typing.get_origin(tp) is dict:
        return "table"
    return str(tp)


def toml_value(value: Any) -> str:
    """A default written as TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def _default(f: dataclasses.Field) -> tuple[str, bool]:
    """(the default as TOML or a word, whether the key is required)."""
    if f.default is not dataclasses.MISSING:
        d = f.default
        if d is None:
            return "(unset)", False
        if dataclasses.is_dataclass(d):
            return "(table)", False
        return toml_value(d), False
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return "(table)", False
    return "required", True


def rules_text(meta: typing.Mapping[str, Any]) -> str:
    """A field's rules in words: ``one of "a", "b"``, ``> 0``, ``≥ 0``, ``≤ 10``..."""
    out = []
    if "choices" in meta:
        out.append("one of " + ", ".join(toml_value(c) for c in meta["choices"]))
    if "gt" in meta:
        out.append(f"> {meta['gt']:g}")
    if "min" in meta:
        out.append(f"≥ {meta['min']:g}")
    if "max" in meta:
        out.append(f"≤ {meta['max']:g}")
    if "pattern" in meta:
        out.append(f"matches `{meta['pattern']}`")
    return ", ".join(out)


def _flat_keys(cls: type) -> list[tuple[str, type, str]]:
    """The keys a table takes flat besides its own fields: ``[[robots]]``'s driver keys (each
    driver's ``flat_keys``), as (key, the sub-table's dataclass, the driver's name)."""
    if cls.__name__ != "RobotConfig":
        return []
    from controller.config.driver_sections import DRIVER_SPECS

    return [
        (k, spec.section, name)
        for name, spec in DRIVER_SPECS.items()
        if spec.section is not None
        for k in spec.flat_keys
    ]


def config_sections() -> list[Section]:
    """Every table of fleet.toml, in the order of ``FleetConfig``'s fields, nested tables after
    the table that holds them; the top-level keys of each in field order."""
    from controller.config.sections import FleetConfig

    out: list[Section] = []

    def walk(cls: type, header: str, prefix: str) -> None:
        comments = member_comments(cls)
        keys, nested = [], []
        for f, tp in _fields(cls):
            default, required = _default(f)
            keys.append(
                Key(
                    f"{prefix}{f.name}",
                    type_name(tp),
                    default,
                    rules_text(f.metadata),
                    comments.get(f.name, ""),
                    required,
                )
            )
            table = _table_of(tp)
            if table is not None:
                nested.append((f.name, table))
        for key, section, driver in _flat_keys(cls):
            keys.append(
                Key(
                    f"{prefix}{key}",
                    type_name(typing.get_type_hints(section)[key]),
                    "",
                    "",
                    f"the same as {prefix}{driver}.{key} (accepted flat, as before the sub-table)",
                    False,
                )
            )
        out.append(Section(header, class_doc(cls), tuple(keys)))
        for name, (sub, many) in nested:
            path = f"{prefix}{name}"
            walk(sub, f"[[{path}]]" if many else f"[{path}]", f"{path}.")

    for f, tp in _fields(FleetConfig):
        sub, many = _table_of(tp)  # type: ignore[misc]
        walk(sub, f"[[{f.name}]]" if many else f"[{f.name}]", f"{f.name}.")
    return out


# --------------------------------------------------------------------------- JSON Schema


def _json_default(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_json_default(v) for v in value]
    return value


def _schema_of(tp: Any) -> dict[str, Any]:
    tp = _optional(tp)
    prims = {bool: "boolean", int: "integer", float: "number", str: "string"}
    if tp in prims:
        return {"type": prims[tp]}
    if dataclasses.is_dataclass(tp):
        return table_schema(tp)  # type: ignore[arg-type]
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": _schema_of(args[0])}
        return {
            "type": "array",
            "items": [_schema_of(a) for a in args],
            "minItems": len(args),
            "maxItems": len(args),
            "additionalItems": False,
        }
    raise TypeError(f"no schema for config type {tp}")


def _key_schema(f: dataclasses.Field, tp: Any, doc: str) -> dict[str, Any]:
    s = _schema_of(tp)
    meta = f.metadata
    if "choices" in meta:
        s["enum"] = list(meta["choices"])
    if "gt" in meta:
        s["exclusiveMinimum"] = meta["gt"]
    if "min" in meta:
        s["minimum"] = meta["min"]
    if "max" in meta:
        s["maximum"] = meta["max"]
    if "pattern" in meta:
        s["pattern"] = meta["pattern"]
    if doc:
        s["description"] = doc
    d = f.default
    if d is not dataclasses.MISSING and d is not None and not dataclasses.is_dataclass(d):
        s["default"] = _json_default(d)
    return s


def table_schema(cls: type) -> dict[str, Any]:
    """The JSON Schema of one table: its keys (no other), the required ones, their rules."""
    comments = member_comments(cls)
    props: dict[str, Any] = {}
    required = []
    for f, tp in _fields(cls):
        props[f.name] = _key_schema(f, tp, comments.get(f.name, ""))
        if _default(f)[1]:
            required.append(f.name)
    for key, section, driver in _flat_keys(cls):
        sub = {f.name: (f, tp) for f, tp in _fields(section)}
        f, tp = sub[key]
        doc = member_comments(section).get(key, "")
        props[key] = _key_schema(f, tp, f"{doc} (flat form of {driver}.{key})".strip())
    out: dict[str, Any] = {"type": "object"}
    doc = class_doc(cls)
    if doc:
        out["description"] = " ".join(doc.split())
    out["properties"] = props
    if required:
        out["required"] = required
    out["additionalProperties"] = False
    return out


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft-07) of fleet.toml."""
    from controller.config.sections import FleetConfig

    body = table_schema(FleetConfig)
    body.pop("description", None)
    return {
        "$schema": DRAFT,
        "title": "fleet.toml",
        "description": (
            "A fleet-controller config (fleet.toml). Written by `fleet schema` from the config "
            "sections; the rules between keys are `fleet check`'s."
        ),
        **body,
    }
