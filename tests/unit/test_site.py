"""A site's router (``fleet router``) and the site-wide tools, without a network: the merged
ACL keeps each fleet's robots to their own fleet's keys, the merged password dictionary refuses
one user with two passwords, and ``fleet status|estop`` with one ``--config`` per fleet answer
per fleet (the end-to-end run across network namespaces is tests/integration/test_site.py)."""

from __future__ import annotations

import dataclasses
import json
import time

import pytest

from controller.cli import main
from controller.config import ConfigError, parse_config
from controller.config.acl import acl_for, site_acl
from controller.runtime.site import merged_dictionary, site_section
from tests.support.config import base_config_dict, free_port, write_toml


def _fleet(name: str, **zenoh) -> dict:
    data = base_config_dict()
    data["fleet"]["name"] = name
    data["robots"] = data["robots"][:2]  # r1, r2 in every fleet: only the key space differs
    for r in data["robots"]:
        r.update(zenoh_user=f"{name}-{r['id']}", zenoh_password=f"pw-{name}-{r['id']}")
    data["zenoh"] = {
        "listen": ["tcp/127.0.0.1:7447"],
        "user": f"{name}-ctl",
        "password": "x",
        "auth_dictionary": "users.txt",
        "acl": "lab",
        "operators": ["op"],
        **zenoh,
    }
    return data


def _put_keys(acl: dict, subject_id: str, flow: str) -> set[str]:
    rules = {r["id"]: r for r in acl["rules"]}
    keys: set[str] = set()
    for p in acl["policies"]:
        if subject_id in p["subjects"]:
            for rid in p["rules"]:
                r = rules[rid]
                if "put" in r["messages"] and flow in r["flows"]:
                    keys |= set(r["key_exprs"])
    return keys


def test_the_site_acl_keeps_each_fleets_robot_to_its_own_fleets_keys():
    a, b = (parse_config(_fleet(n), n) for n in ("cella", "cellb"))
    acl = site_acl([a, b], backbone=("site",))
    ids = [r["id"] for r in acl["rules"]]
    assert len(ids) == len(set(ids)) and acl["default_permission"] == "deny"
    assert len(acl["rules"]) == len(acl_for(a)["rules"]) + len(acl_for(b)["rules"]) + 1
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["cella:robot-r1"]["usernames"] == ["cella-r1"]
    assert subjects["cellb:robot-r1"]["usernames"] == ["cellb-r1"]
    # robot r1 of fleet A puts only its own pose and event, is sent only its cmd and A's e-stop
    assert _put_keys(acl, "cella:robot-r1", "ingress") == {
        "fleet/cella/robot/r1/pose",
        "fleet/cella/robot/r1/event",
    }
    assert _put_keys(acl, "cella:robot-r1", "egress") == {
        "fleet/cella/robot/r1/cmd",
        "fleet/cella/estop",
    }
    # every put rule a fleet's robot has names that fleet's keys only
    for s in subjects:
        if ":robot-" in s:
            fleet = s.split(":")[0]
            for flow in ("ingress", "egress"):
                assert all(k.startswith(f"fleet/{fleet}/") for k in _put_keys(acl, s, flow))
    # the backbone router may do everything; without one, no such rule
    assert _put_keys(acl, "site:backbone", "ingress") == {"**"}
    assert subjects["site:backbone"]["usernames"] == ["site"]
    assert "site:backbone" not in {s["id"] for s in site_acl([a, b])["subjects"]}


def test_a_site_router_merges_dictionaries_and_refuses_a_user_with_two_passwords(tmp_path):
    (tmp_path / "a.txt").write_text("op:1\ncella-r1:2\n")
    (tmp_path / "b.txt").write_text("# fleet B\nop:1\ncellb-r1:3\n")
    out = tmp_path / "users.txt"
    assert merged_dictionary([str(tmp_path / "a.txt"), str(tmp_path / "b.txt")], out) == 3
    assert sorted(out.read_text().split()) == ["cella-r1:2", "cellb-r1:3", "op:1"]
    assert out.stat().st_mode & 0o077 == 0  # the passwords readable by their owner only
    (tmp_path / "c.txt").write_text("op:other\n")
    with pytest.raises(ConfigError, match="'op' has another password"):
        merged_dictionary([str(tmp_path / "a.txt"), str(tmp_path / "c.txt")], out)


def test_a_site_router_refuses_a_fleet_it_cannot_merge(tmp_path):
    a = parse_config(_fleet("cella"), "a")
    bare = parse_config(_fleet("cellb", acl="", operators=[]), "b")
    with pytest.raises(ConfigError, match="every fleet of a secured site router"):
        site_section([a, bare], "users.txt", ())
    section = site_section([a], "users.txt", ("site",))
    assert section.auth_dictionary == "users.txt" and not section.user
    assert json.loads(section.acl_block)["subjects"][-1]["usernames"] == ["site"]
    own = dataclasses.replace(a, zenoh=dataclasses.replace(a.zenoh, acl="/x.json5", acl_block=""))
    with pytest.raises(ConfigError, match="'lab' profile only"):
        site_section([own], "users.txt", ())


def test_site_status_and_estop_answer_per_fleet_and_fail_when_one_fleet_does(tmp_path, capsys):
    paths = []
    for name in ("cella", "cellb"):
        data = base_config_dict()
        data["fleet"]["name"] = name
        data["zenoh"] = {"listen": [f"tcp/127.0.0.1:{free_port()}"]}  # nobody listens there
        paths += ["--config", str(write_toml(tmp_path / f"{name}.toml", data))]
    t0 = time.monotonic()
    assert main(["estop", *paths, "--json", "--timeout", "1"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert time.monotonic() - t0 < 15  # both fleets at once, not one after the other's timeout
    assert out["ok"] is False and out["confirmed"] is False and out["engaged"] is True
    assert [f["fleet"] for f in out["fleets"]] == ["cella", "cellb"]
    assert "cella/r1" in out["agents_missing"] and "cellb/r6" in out["agents_missing"]
    assert main(["status", *paths, "--timeout", "1"]) == 1
    text = capsys.readouterr()
    assert text.out.startswith("site: 0 of 2 fleets answered; NO DAEMON ANSWERED for cella, cellb")
    assert "[cellb] fleet status: no daemon of fleet 'cellb' answered" in text.err
    assert main(["status", "--config", paths[1], "--config", paths[1]]) == 2
    assert "fleet 'cella' given twice" in capsys.readouterr().err
