"""The security keys of [zenoh] and [[robots]]: validation with key paths, files checked when a
session is built, the generated lab ACL profile, the exposed-listen warning, no password in
logs. No session is opened here (tests/integration/test_secure_bus.py does that)."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys

import pytest

from controller.acl import acl_for, acl_json5
from controller.config import (
    ConfigError,
    ZenohSection,
    config_to_dict,
    load_config,
    parse_config,
)
from controller.io.bus import zenoh_config
from tests.support.config import ROOT, base_config_dict, write_toml

LAB = ROOT / "lab"


def _data(zenoh: dict, robots: dict | None = None) -> dict:
    data = base_config_dict()
    data["robots"] = data["robots"][:2]
    data["zenoh"] = {"listen": ["tcp/127.0.0.1:7447"], **zenoh}
    for r in data["robots"]:
        r.update({k: v.format(id=r["id"]) for k, v in (robots or {}).items()})
    return data


SECURE = {"user": "ctl", "password": "x", "auth_dictionary": "users.txt"}
ROBOT_USERS = {"zenoh_user": "{id}", "zenoh_password": "pw-{id}"}


@pytest.mark.parametrize(
    ("zenoh", "robots", "path", "words"),
    [
        ({"user": "ctl"}, None, "zenoh.password", "needs a password"),
        ({"user": "ctl", "password": "a", "password_file": "f"}, None, "zenoh.password_file", ""),
        ({"password": "a"}, None, "zenoh.user", "without a user"),
        ({}, {"zenoh_password": "p"}, "robots[0].zenoh_user", ""),
        ({"tls": {"certificate": "c", "private_key": "k"}}, None, "zenoh.tls.root_ca", ""),
        (
            {"tls": {"certificate": "c", "private_key": "k", "root_ca": "ca"}},
            None,
            "zenoh.listen[0]",
            "tls/127.0.0.1:7447",
        ),
        ({"tls": {"certifcate": "c"}}, None, "zenoh.tls.certifcate", "did you mean 'certificate'"),
        ({"acl": "lba"}, None, "zenoh.acl", "did you mean 'lab'"),
        ({"acl": "lab", "user": "ctl", "password": "x"}, ROBOT_USERS, "zenoh.acl", "dictionary"),
        ({"acl": "lab", **SECURE}, None, "robots[0].zenoh_user", "own identity"),
        ({"acl": "lab", "auth_dictionary": "d"}, ROBOT_USERS, "zenoh.user", ""),
        ({"operators": ["a:b"]}, None, "zenoh.operators[0]", ""),
        ({"usr": "ctl"}, None, "zenoh.usr", "did you mean 'user'"),
    ],
)
def test_bad_security_keys_name_their_key_path(zenoh, robots, path, words):
    with pytest.raises(ConfigError) as err:
        parse_config(_data(zenoh, robots), "t.toml")
    assert err.value.path == path, err.value
    assert words in str(err.value)


def test_files_are_relative_to_the_config_and_checked_when_a_session_needs_them(tmp_path):
    (tmp_path / "ctl.pw").write_text("secret\n")
    data = _data(
        {"acl": "lab", "user": "ctl", "password_file": "ctl.pw", "auth_dictionary": "users.txt"},
        {"zenoh_user": "{id}", "zenoh_password_file": "{id}.pw"},
    )
    cfg = load_config(write_toml(tmp_path / "fleet.toml", data))
    assert cfg.zenoh.password_file == str(tmp_path / "ctl.pw")
    # the hub needs its dictionary (missing here), named by its key
    with pytest.raises(ConfigError) as err:
        zenoh_config(cfg.zenoh)
    assert err.value.path == "zenoh.auth_dictionary" and "users.txt" in str(err.value)
    # a robot's side never reads the hub's dictionary, but needs its own password file
    with pytest.raises(ConfigError) as err:
        zenoh_config(cfg.zenoh, listen=[], identity=cfg.zenoh_identity("r2"))
    assert err.value.path == "robots[1].zenoh_password_file"
    (tmp_path / "r2.pw").write_text("pw2\n")
    conf = zenoh_config(cfg.zenoh, listen=[], identity=cfg.zenoh_identity("r2"))
    assert json.loads(conf.get_json("transport/auth/usrpwd")) == {
        "user": "r2",
        "password": "pw2",
        "dictionary_file": None,
    }
    assert json.loads(conf.get_json("access_control"))["enabled"] is False  # not the hub
    # the hub, once its dictionary exists: its user, the dictionary and the generated ACL
    (tmp_path / "users.txt").write_text("ctl:secret\nr1:a\nr2:pw2\n")
    conf = zenoh_config(cfg.zenoh)
    auth = json.loads(conf.get_json("transport/auth/usrpwd"))
    assert auth["user"] == "ctl" and auth["password"] == "secret"
    assert auth["dictionary_file"] == str(tmp_path / "users.txt")
    acl = json.loads(conf.get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"


@pytest.mark.parametrize("key", ["config_file", "acl"])
def test_missing_config_or_acl_file_is_named(tmp_path, key):
    value = str(tmp_path / ("nope.json5"))
    cfg = parse_config(_data({key: value}), "t")
    with pytest.raises(ConfigError) as err:
        zenoh_config(cfg.zenoh)
    assert err.value.path == f"zenoh.{key}" and "nope.json5" in str(err.value)


def test_config_file_is_the_base_and_our_settings_win(tmp_path):
    (tmp_path / "z.json5").write_text(
        '// a site file\n{ mode: "router", transport: { link: { tx: { lease: 4321 } } } }\n'
    )
    cfg = parse_config(_data({"config_file": str(tmp_path / "z.json5")}), "t")
    conf = zenoh_config(cfg.zenoh)
    assert json.loads(conf.get_json("transport/link/tx/lease")) == 4321
    assert json.loads(conf.get_json("mode")) == "peer"


def test_a_lost_hub_is_retried_within_reconnect_s():
    """Every session retries a lost connect endpoint after 0.25 s, doubling up to
    zenoh.reconnect_s (1 s); 0 leaves zenoh's own back-off (1 s doubling to 4 s)."""
    retry = json.loads(zenoh_config(ZenohSection()).get_json("connect/retry"))
    assert retry["period_init_ms"] == 250 and retry["period_max_ms"] == 1000
    assert retry["period_increase_factor"] == 2
    own = json.loads(zenoh_config(ZenohSection(reconnect_s=0.0)).get_json("connect/retry"))
    assert own is None  # not set: zenoh's default applies


def test_exposed_listen_without_auth_warns_once(caplog, tmp_path):
    caplog.set_level(logging.WARNING, logger="controller.io.bus")
    for ep in ("tcp/127.0.0.1:7447", "tcp/[::1]:7447", "tcp/localhost:7447"):
        zenoh_config(ZenohSection(listen=(ep,)))
    assert caplog.records == []
    zenoh_config(ZenohSection(listen=("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7448")))
    warnings = [r for r in caplog.records if "INSECURE" in r.getMessage()]
    assert len(warnings) == 1 and "tcp/0.0.0.0:7447" in warnings[0].getMessage()
    assert "127.0.0.1" not in warnings[0].getMessage()
    caplog.clear()
    (tmp_path / "d.txt").write_text("a:b\n")
    zenoh_config(
        ZenohSection(listen=("tcp/0.0.0.0:7447",), auth_dictionary=str(tmp_path / "d.txt"))
    )
    assert caplog.records == []


def test_lab_acl_profile_rules_per_robot():
    cfg = parse_config(_data({"acl": "lab", **SECURE, "operators": ["op"]}, ROBOT_USERS), "t")
    acl = acl_for(cfg)
    assert acl == json.loads(cfg.zenoh.acl_block)
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s for s in acl["subjects"]}
    by_subject = {p["subjects"][0]: p["rules"] for p in acl["policies"]}
    assert acl["default_permission"] == "deny"
    assert subjects["robot-r1"] == {"id": "robot-r1", "usernames": ["r1"]}
    assert subjects["controller"]["usernames"] == ["ctl"]
    assert subjects["operators"]["usernames"] == ["op"]
    r1 = [rules[r] for r in by_subject["robot-r1"]]
    puts_in = [k for r in r1 if r["messages"] == ["put"] and r["flows"] == ["ingress"]
               for k in r["key_exprs"]]  # fmt: skip
    puts_out = [k for r in r1 if r["messages"] == ["put"] and r["flows"] == ["egress"]
                for k in r["key_exprs"]]  # fmt: skip
    assert puts_in == ["fleet/lab/robot/r1/pose", "fleet/lab/robot/r1/event"]
    assert puts_out == ["fleet/lab/robot/r1/cmd", "fleet/lab/estop"]
    op = [rules[r] for r in by_subject["operators"]]
    assert any(r["key_exprs"] == ["fleet/lab/estop"] and r["flows"] == ["ingress"] for r in op)
    # nobody but the controller puts anything else: every put/delete rule is one of the above
    everyone = [rules[r] for r in by_subject["everyone"]]
    assert not any({"put", "delete"} & set(r["messages"]) for r in everyone)


def test_shipped_lab_profile_loads_and_its_acl_file_is_generated_from_it():
    cfg = load_config(LAB / "secure.toml")
    assert cfg.zenoh.acl == "lab" and cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert [r.zenoh_user for r in cfg.robots] == list(cfg.robot_ids)
    shipped = (LAB / "acl.json5").read_text()
    assert shipped == acl_json5(cfg), (
        "regenerate: python -m controller.acl lab/secure.toml lab/acl.json5"
    )


def test_passwords_never_reach_logs_and_the_dict_loads_again():
    cfg = parse_config(_data({**SECURE, "acl": "lab"}, ROBOT_USERS), "t")
    d = config_to_dict(cfg)
    text = json.dumps(d)
    assert '"x"' not in text and "pw-r1" not in text and "acl_block" not in text
    assert d["zenoh"]["password"] == "<redacted>"
    d.pop("source", None)
    assert parse_config(d, "again").zenoh.user == "ctl"


def test_cli_exits_2_naming_a_missing_password_file(tmp_path):
    data = _data({"user": "ctl", "password_file": "missing.pw"})
    path = write_toml(tmp_path / "f.toml", data)
    proc = subprocess.run(
        [sys.executable, "-m", "controller.cli", "status", "--config", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert proc.returncode == 2, proc.stderr
    assert "zenoh.password_file" in proc.stderr and "missing.pw" in proc.stderr
