"""fleet.toml → Python data: the error type with key paths, and the walker.

Every section is a frozen dataclass whose fields carry their own rules in ``metadata``
(``min``, ``max``, ``gt`` for a strict lower bound, ``choices``), declared with :func:`_rule`.
The walker converts TOML tables against those dataclasses, so an unknown key, a wrong type or an
out-of-range value is reported with the file, the full key path, what was expected and, for
unknown keys, a did-you-mean. It knows no section: those are controller/config/sections.py.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import difflib
import math
import re
import tomllib
import types
import typing
from collections.abc import Iterator
from dataclasses import field
from pathlib import Path
from typing import Any

#: TOML tables and arrays nested deeper than this are refused (no key of ours is deeper than 4)
MAX_TOML_DEPTH = 32


class ConfigError(ValueError):
    """A config that does not validate; ``path`` is the dotted key path of the culprit."""

    def __init__(self, source: str, path: str, message: str):
        self.source = source
        self.path = path
        self.message = message
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{path or '<root>'}: {message}")


class ConfigErrors(ConfigError):
    """Every error found in one pass over a config (``parse_config(..., all_errors=True)``,
    ``fleet check``), in the order found; it reads as the first one, so a handler of one
    ConfigError shows what it showed before."""

    def __init__(self, errors: list[ConfigError]):
        first = errors[0]
        super().__init__(first.source, first.path, first.message)
        self.errors = list(errors)


class _Reported(Exception):
    """A table, array or rule whose errors are already collected: what holds it cannot be
    built or checked either (raised only while collecting)."""


#: the errors being collected (:func:`collecting`), or None: the first error is raised
_COLLECT: contextvars.ContextVar[list[ConfigError] | None] = contextvars.ContextVar(
    "config_errors", default=None
)


@contextlib.contextmanager
def collecting() -> Iterator[list[ConfigError]]:
    """Within it the walker and the cross-field rules note each independent error in the list
    yielded and go on (:func:`found`) instead of raising the first one."""
    token = _COLLECT.set([])
    try:
        yield _COLLECT.get()  # type: ignore[misc]
    finally:
        _COLLECT.reset(token)


def found(exc: ConfigError) -> None:
    """Raise ``exc``, or, while :func:`collecting`, note it and return."""
    errors = _COLLECT.get()
    if errors is None:
        raise exc
    errors.append(exc)


def attempt(fn: typing.Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)``; while :func:`collecting`, a ConfigError it raises is noted and
    :data:`FAILED` returned (and so for one whose errors it noted itself)."""
    errors = _COLLECT.get()
    n = len(errors) if errors is not None else 0
    try:
        out = fn(*args)
    except ConfigError as exc:
        found(exc)
        return FAILED
    except _Reported:
        return FAILED
    return FAILED if errors is not None and len(errors) > n else out


FAILED: Any = object()  # what :func:`attempt` returns for a rule that failed


class InputError(ValueError):
    """Bad input other than the config: a missing or unreadable file, an option out of range
    (the CLI exits 2 with the message)."""


def _rule(default: Any = dataclasses.MISSING, **meta: Any) -> Any:
    if default is dataclasses.MISSING:
        return field(metadata=meta)
    if isinstance(default, list | dict):
        raise TypeError("use tuples for defaults")
    return field(default=default, metadata=meta)


# --------------------------------------------------------------------------- the walker


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if dataclasses.is_dataclass(tp):
        return "a table"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            inner = _type_name(args[0])
            if inner.startswith("an array of "):
                return "an array of arrays of " + inner.removeprefix("an array of ")
            return f"an array of {inner.removeprefix('a ').removeprefix('an ')}s"
        return f"an array of {len(args)} items"
    return str(tp)


def _scalar(tp: type, value: Any, path: str, src: str) -> Any:
    """A bool, int, float or str value checked against its type (a bool is never a number)."""
    is_bool = isinstance(value, bool)
    if tp is bool:
        ok = is_bool
    elif tp is int:
        ok = not is_bool and isinstance(value, int)
    elif tp is float:
        ok = not is_bool and isinstance(value, int | float)
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {value!r}")
    if tp is float:
        if not math.isfinite(value):
            raise ConfigError(src, path, f"expected a finite number, got {value!r}")
        return float(value)
    return value


def _tuple(tp: Any, value: Any, path: str, src: str) -> tuple:
    """A TOML array as a tuple: ``tuple[T, ...]`` of any length or a fixed ``tuple[A, B]``."""
    args = typing.get_args(tp)
    if not isinstance(value, list):
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:  # each item on its own ([[robots]] entries)
        items = [attempt(_convert, args[0], v, f"{path}[{i}]", src) for i, v in enumerate(value)]
        if FAILED in items:
            raise _Reported
        return tuple(items)
    if len(value) != len(args):
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {len(value)}: {value!r}")
    return tuple(
        _convert(a, v, f"{path}[{i}]", src)
        for i, (a, v) in enumerate(zip(args, value, strict=True))
    )


def _convert(tp: Any, value: Any, path: str, src: str) -> Any:
    """A TOML value converted to the dataclass field type ``tp`` (ConfigError naming ``path``)."""
    if tp in (bool, int, float, str):
        return _scalar(tp, value, path, src)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(src, path, f"expected a table, got {value!r}")
        return _build(tp, value, path, src)
    if typing.get_origin(tp) is tuple:
        return _tuple(tp, value, path, src)
    if isinstance(tp, types.UnionType):  # an optional key (T | None): present means T
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(inner) == 1:
            return _convert(inner[0], value, path, src)
    raise TypeError(f"unsupported config type {tp}")


def _check_rules(meta: typing.Mapping[str, Any], value: Any, path: str, src: str) -> None:
    if "choices" in meta and value not in meta["choices"]:
        choices = ", ".join(repr(c) for c in meta["choices"])
        raise ConfigError(src, path, f"expected one of {choices}, got {value!r}")
    if "gt" in meta and not value > meta["gt"]:
        raise ConfigError(src, path, f"expected a value > {meta['gt']}, got {value!r}")
    if "min" in meta and not value >= meta["min"]:
        raise ConfigError(src, path, f"expected a value >= {meta['min']}, got {value!r}")
    if "max" in meta and not value <= meta["max"]:
        raise ConfigError(src, path, f"expected a value <= {meta['max']}, got {value!r}")
    if "pattern" in meta and not re.match(meta["pattern"], value):
        raise ConfigError(
            src, path, f"expected letters, digits, '_' or '-' (a bus key segment), got {value!r}"
        )


_NOT_KEYS = ("source", "notes")  # FleetConfig fields the loader fills, never TOML keys


def _build(cls: type, table: dict[str, Any], path: str, src: str) -> Any:
    merge = getattr(cls, "merge_table", None)  # a section that takes some keys two ways
    if merge is not None:
        table = merge(table, path, src)
    hints = typing.get_type_hints(cls)
    fields = {
        f.name: f
        for f in dataclasses.fields(cls)
        if f.name not in _NOT_KEYS and not f.metadata.get("internal")
    }
    bad = False
    for key in table:
        if key not in fields:
            where = f"{path}.{key}" if path else key
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            valid = ", ".join(fields)
            found(ConfigError(src, where, f"unknown key{hint} (valid keys: {valid})"))
            bad = True
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        where = f"{path}.{name}" if path else name
        if name in table:
            kwargs[name] = attempt(_field, hints[name], f.metadata, table[name], where, src)
            bad = bad or kwargs[name] is FAILED
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            found(ConfigError(src, where, f"missing required key ({_type_name(hints[name])})"))
            bad = True
    if bad:
        raise _Reported
    return cls(**kwargs)


def _field(tp: Any, meta: typing.Mapping[str, Any], value: Any, path: str, src: str) -> Any:
    value = _convert(tp, value, path, src)
    _check_rules(meta, value, path, src)
    return value


def parse_table(cls: type, table: Any, path: str, source: str = "") -> Any:
    """Validate a TOML table against a config dataclass (unknown keys, types, ranges), as the
    loader does for fleet.toml; raises ConfigError naming ``source`` and the key path."""
    return _convert(cls, table, path, source)


def override(section: Any, values: dict[str, Any], source: str, prefix: str = "") -> Any:
    """A copy of a config section with some fields replaced, each checked by the field's rules
    (e.g. command-line overrides); raises ConfigError naming ``prefix + key``."""
    hints = typing.get_type_hints(type(section))
    fields = {f.name: f for f in dataclasses.fields(section)}
    checked = {}
    for key, value in values.items():
        where = f"{prefix}{key}"
        value = _convert(hints[key], value, where, source)
        _check_rules(fields[key].metadata, value, where, source)
        checked[key] = value
    return dataclasses.replace(section, **checked)


def nesting_error(data: Any, limit: int = MAX_TOML_DEPTH) -> tuple[str, str] | None:
    """(key path, message) when tables or arrays nest deeper than ``limit``, else None.
    Iterative: a document of any depth is walked without recursion."""
    stack: list[tuple[Any, str, int]] = [(data, "", 0)]
    while stack:
        value, path, depth = stack.pop()
        if depth > limit:
            top = re.split(r"[.\[]", path, maxsplit=1)[0] or path
            return top, f"tables or arrays nested deeper than {limit} levels"
        if isinstance(value, dict):
            stack.extend(
                (v, f"{path}.{k}" if path else str(k), depth + 1) for k, v in value.items()
            )
        elif isinstance(value, list):
            stack.extend((v, f"{path}[{i}]", depth + 1) for i, v in enumerate(value))
    return None


def read_toml(path: str | Path) -> dict[str, Any]:
    """A TOML file as data (ConfigError naming the file when it cannot be read, is not text, is
    not TOML or nests too deep for the parser)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (Windows editors) is fine
    except OSError as exc:
        raise ConfigError(str(p), "", f"cannot read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(
            str(p), "", f"not a text file (not UTF-8 at byte {exc.start}): expected TOML"
        ) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(p), "", f"not valid TOML: {exc}") from exc
    except RecursionError:  # tomllib recurses per nested array or inline table
        raise ConfigError(
            str(p), "", f"not a config: arrays or tables nested deeper than {MAX_TOML_DEPTH}"
        ) from None
    return data
