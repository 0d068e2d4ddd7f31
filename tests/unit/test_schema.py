"""The JSON Schema of fleet.toml (``fleet schema``, controller/config/schema.py): it is made from
the config sections, the shipped configs name it on their first line (Taplo / Even Better TOML)
and pass it, and it refuses what ``fleet check`` refuses key by key (unknown key, wrong type,
out of range, a name not in the registry)."""

from __future__ import annotations

import functools
import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from controller.cli import main
from controller.config import ConfigError, parse_config
from controller.config.schema import json_schema
from controller.docs import schema_text
from tests.support.config import ROOT

SHIPPED = sorted(
    [ROOT / "fleet.toml", ROOT / "lab.toml", ROOT / "lab" / "secure.toml"]
    + list((ROOT / "controller" / "examples").glob("*.toml")),
)


SCHEMA_TEXT = schema_text()


@functools.cache
def _validator() -> jsonschema.Draft7Validator:
    schema = json_schema()
    jsonschema.Draft7Validator.check_schema(schema)
    return jsonschema.Draft7Validator(schema)


def _errors(data: dict) -> list[str]:
    return [e.message for e in _validator().iter_errors(data)]


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_shipped_config_names_the_schema_and_passes_it(path: Path):
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("#:schema "), f"{path}: first line {first!r}"
    target = (path.parent / first.removeprefix("#:schema ").strip()).resolve()
    assert target.is_file(), f"{path} names {target}, which is missing"
    assert target.read_text(encoding="utf-8") == SCHEMA_TEXT, "run python -m controller.docs"
    assert _errors(tomllib.loads(path.read_text(encoding="utf-8"))) == []


BROKEN = {
    "an unknown key": ("fleet", "rate", 20.0),
    "a wrong type": ("fleet", "rate_hz", "fast"),
    "a number out of range": ("fleet", "rate_hz", -1.0),
    "a name not in the registry": ("transport", "strategy", "teleport"),
    "an integer as a float": ("capture", "population", 60.5),
    "a bool as a number": ("fleet", "cmd_ttl", True),
}


@pytest.mark.parametrize("what", BROKEN)
def test_a_broken_config_fails_the_schema_as_it_fails_fleet_check(what):
    table, key, value = BROKEN[what]
    data = tomllib.loads((ROOT / "fleet.toml").read_text(encoding="utf-8"))
    data.setdefault(table, {})[key] = value
    assert _errors(data), f"the schema accepted {what}"
    with pytest.raises(ConfigError) as err:  # what fleet check runs on the parsed file
        parse_config(data, "fleet.toml", all_errors=True)
    assert f"{table}.{key}" in str(err.value)


def test_a_robot_without_its_required_keys_and_an_extra_table_fail():
    data = tomllib.loads((ROOT / "fleet.toml").read_text(encoding="utf-8"))
    del data["robots"][0]["kind"]
    data["robots"][1]["mavlink"] = {"url": "udpin:127.0.0.1:14550", "colour": "red"}
    messages = " ".join(_errors(data))
    assert "'kind' is a required property" in messages and "colour" in messages


def test_flat_mavlink_keys_are_accepted_as_the_loader_accepts_them():
    data = tomllib.loads((ROOT / "fleet.toml").read_text(encoding="utf-8"))
    data["robots"][0].update(url="udpin:127.0.0.1:14550", system_id=3)
    assert _errors(data) == []


def test_fleet_schema_prints_and_writes_the_committed_schema(tmp_path, capsys):
    assert main(["schema"]) == 0
    assert capsys.readouterr().out == SCHEMA_TEXT
    out = tmp_path / "sub" / "fleet.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == (ROOT / "fleet.schema.json").read_text()
    assert json.loads(out.read_text())["properties"]["robots"]["type"] == "array"


def test_fleet_init_writes_the_schema_its_example_names_beside_it(tmp_path, capsys):
    out = tmp_path / "cfg" / "lab.toml"
    assert main(["init", "mavlink", "--out", str(out)]) == 0
    first = out.read_text(encoding="utf-8").splitlines()[0]
    named = out.parent / first.removeprefix("#:schema ").strip()
    assert named.read_text(encoding="utf-8") == SCHEMA_TEXT
    assert f"wrote {named}" in capsys.readouterr().out
    named.write_text("{}", encoding="utf-8")  # one of the user's own is left alone
    assert main(["init", "rehearsal", "--out", str(out.parent / "rehearsal.toml")]) == 0
    assert named.read_text(encoding="utf-8") == "{}"
