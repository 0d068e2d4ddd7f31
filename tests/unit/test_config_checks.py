"""`fleet check` catches what `fleet run` would crash on: each case exits 2 naming the key or
the file, and `fleet run` refuses the same config with the same exit status before it starts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.cli import main
from controller.config import ConfigError, endpoint_error, load_config
from tests.support.certs import make_certs, openssl_missing
from tests.support.config import base_config_dict, write_toml


def _write(tmp_path: Path, mutate) -> Path:
    data = base_config_dict()
    data["log"]["dir"] = str(tmp_path / "runs")
    mutate(data)
    return write_toml(tmp_path / "bad.toml", data)


def _check_fails(path: Path, key: str, words: str, capsys) -> None:
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert key in err and words in err, err
    assert main(["check", "--config", str(path), "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and out["path"] == key and out["file"] == str(path)


def _set(section: str, key: str, value):
    def mutate(d):
        d.setdefault(section, {})[key] = value

    return mutate


def _robot_start(i: int, start):
    def mutate(d):
        d["robots"][i]["start"] = start

    return mutate


def _with_zenoh(**keys):
    """[zenoh] with the controller's identity ``ctl`` and an operator ``op``, plus ``keys``."""

    def mutate(d):
        d["zenoh"].update(user="ctl", password="x", operators=["op"])
        d["zenoh"].update(keys)

    return mutate


def _robot_users(*users: str):
    def mutate(d):
        _with_zenoh()(d)
        for r, user in zip(d["robots"], users, strict=False):
            r.update(zenoh_user=user, zenoh_password=f"pw-{user}")

    return mutate


def _robot_certs(*certs: str):
    def mutate(d):
        for r, cert in zip(d["robots"], certs, strict=False):
            r.update(zenoh_certificate=cert, zenoh_private_key=cert + ".key")

    return mutate


def _robot_on_robot(d):
    x, y, _ = d["robots"][0]["start"]
    d["robots"][3]["start"] = [x + 0.15, y, 0.0]  # radii 0.1 + 0.1 > 0.15


CASES = {
    # name: (mutate, key path, words in the message)
    "listen-not-an-endpoint": (
        _set("zenoh", "listen", ["tcp/not-an-endpoint"]),
        "zenoh.listen[0]",
        "expected tcp/HOST:PORT",
    ),
    "listen-port-out-of-range": (
        _set("zenoh", "listen", ["tcp/127.0.0.1:70000"]),
        "zenoh.listen[0]",
        "0..65535",
    ),
    "connect-port-zero": (
        _set("zenoh", "connect", ["tcp/127.0.0.1:7447", "udp/127.0.0.1:0"]),
        "zenoh.connect[1]",
        "1..65535",
    ),
    "connect-bad-ipv4": (
        _set("zenoh", "connect", ["quic/300.0.0.1:7447"]),
        "zenoh.connect[0]",
        "not an IPv4 address",
    ),
    "unknown-protocol": (
        _set("zenoh", "listen", ["http/127.0.0.1:80"]),
        "zenoh.listen[0]",
        "PROTOCOL one of tcp",
    ),
    "no-protocol": (
        _set("zenoh", "listen", ["127.0.0.1:7447"]),
        "zenoh.listen[0]",
        "not a zenoh endpoint",
    ),
    "robots-overlap": (_robot_on_robot, "robots[3].start", "overlaps robot"),
    "robot-on-obstacle": (
        _robot_start(1, [5.55, 5.4, 0.0]),  # 5 cm off the bench's west edge, radius 0.1
        "robots[1].start",
        "overlaps obstacles[0]",
    ),
    "robot-inside-obstacle": (
        _robot_start(2, [9.3, 2.8, 0.0]),
        "robots[2].start",
        "overlaps obstacles[1]",
    ),
    # issue 22 item 7: the gaps of fleet check
    "timestep-absurdly-small": (_set("sim", "timestep", 1e-9), "sim.timestep", ">= 0.0001"),
    "timestep-longer-than-a-tick": (
        _set("sim", "timestep", 0.1),  # fleet.rate_hz = 20: one tick is 0.05 s
        "sim.timestep",
        "longer than one control tick",
    ),
    "tls-listen-without-tls-files": (
        _set("zenoh", "listen", ["tls/127.0.0.1:7447"]),
        "zenoh.listen[0]",
        "zenoh.tls is not set",
    ),
    "tls-connect-without-tls-files": (
        _set("zenoh", "connect", ["tls/127.0.0.1:7447"]),
        "zenoh.connect[0]",
        "root_ca",
    ),
    "two-robots-one-user": (_robot_users("r", "r"), "robots[1].zenoh_user", "one identity"),
    "robot-is-the-controller": (
        _robot_users("ctl", "r2"),
        "robots[0].zenoh_user",
        "zenoh.user (the controller)",
    ),
    "robot-is-an-operator": (
        _robot_users("r1", "op"),
        "robots[1].zenoh_user",
        "an operator",
    ),
    "operator-is-the-controller": (
        _with_zenoh(operators=["ctl"]),
        "zenoh.operators[0]",
        "one identity",
    ),
    "two-robots-one-certificate": (
        _robot_certs("c.pem", "c.pem"),
        "robots[1].zenoh_certificate",
        "one certificate",
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_check_and_load_name_the_key(tmp_path, capsys, name):
    mutate, key, words = CASES[name]
    path = _write(tmp_path, mutate)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert err.value.path == key and words in err.value.message
    _check_fails(path, key, words, capsys)


def test_touching_robots_are_fine(tmp_path):
    def mutate(d):
        x, y, _ = d["robots"][0]["start"]
        d["robots"][3]["start"] = [x + 0.2, y, 0.0]  # radii 0.1 + 0.1: touching

    load_config(_write(tmp_path, mutate))


@pytest.mark.parametrize(
    "endpoint",
    [
        "tcp/127.0.0.1:7447",
        "tcp/localhost:7447",
        "udp/[::1]:7447",
        "tls/lab-hub.example.org:7447#root_ca_certificate=/etc/ca.pem",
        "quic/10.0.0.2:7447",
        "unixsock-stream//tmp/zenoh.sock",
    ],
)
def test_good_endpoints(endpoint):
    assert endpoint_error(endpoint, listen=False) is None


def test_listen_on_port_zero_is_any_free_port():
    assert endpoint_error("tcp/127.0.0.1:0", listen=True) is None


@pytest.mark.parametrize(
    "content", [b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe", b"\xff\xfe\x00[fleet]"]
)
def test_binary_file_exits_2_naming_the_file(tmp_path, capsys, content):
    path = tmp_path / "binary.toml"
    path.write_bytes(content)
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "not a text file" in err and "Traceback" not in err


def test_unreadable_file_exits_2_naming_the_file(tmp_path, capsys):
    path = tmp_path / "adir.toml"
    path.mkdir()  # a directory: unreadable as a file, also for root
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "cannot read" in err


def test_unwritable_log_dir_exits_2(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("not a directory")
    path = _write(tmp_path, _set("log", "dir", str(blocker / "runs")))
    load_config(path)  # the config itself is fine: only the file system says no
    _check_fails(path, "log.dir", "is not a directory", capsys)
    assert not (blocker / "runs").exists()


def test_a_state_folder_that_cannot_keep_the_estop_exits_2(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("not a directory")
    path = _write(tmp_path, _set("fleet", "state_dir", str(blocker / "state")))
    _check_fails(path, "fleet.state_dir", "the e-stop latch", capsys)
    path = _write(tmp_path, _set("log", "state_dir", str(blocker / "state")))
    _check_fails(path, "log.state_dir", "is not a directory", capsys)


def test_fleet_run_refuses_the_same_before_starting(tmp_path, capsys):
    """`fleet run` gets the same checks: exit 2 naming the key, nothing started."""
    bad_zenoh = _write(tmp_path, _set("zenoh", "listen", ["tcp/not-an-endpoint"]))
    assert main(["run", "--config", str(bad_zenoh), "--backend", "ideal"]) == 2
    assert "zenoh.listen[0]" in capsys.readouterr().err
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    bad_log = _write(tmp_path, _set("log", "dir", str(blocker / "runs")))
    assert main(["run", "--config", str(bad_log), "--backend", "ideal"]) == 2
    assert "log.dir" in capsys.readouterr().err
    out = blocker / "sub" / "run.mcap"
    assert main(["run", "--config", str(bad_zenoh.parent / "bad.toml"), "--out", str(out)]) == 2
    assert "--out" in capsys.readouterr().err


def test_distinct_identities_are_fine(tmp_path):
    cfg = load_config(_write(tmp_path, _robot_users("r1", "r2", "r3")))
    assert [r.zenoh_user for r in cfg.robots[:3]] == ["r1", "r2", "r3"]


@pytest.mark.parametrize("nest", ["[", "{a = "])
def test_deeply_nested_toml_exits_2_without_a_traceback(tmp_path, capsys, nest):
    """5 000 nested arrays (or inline tables) made tomllib raise RecursionError (a traceback)."""
    close = "]" if nest == "[" else "}"
    path = tmp_path / "deep.toml"
    path.write_text("x = " + nest * 5000 + "1" + close * 5000 + "\n")
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "nested deeper than" in err and "Traceback" not in err


def test_deep_tables_that_parse_are_bounded_too(tmp_path, capsys):
    """[a.a.a. ... ] 5 000 deep parses; the nesting bound names its top key."""
    path = tmp_path / "deep.toml"
    path.write_text("[" + ".".join(["deep"] * 5000) + "]\nx = 1\n")
    assert main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: deep: " in err and "nested deeper than 32" in err


def test_timestep_of_one_tick_is_accepted(tmp_path):
    cfg = load_config(_write(tmp_path, _set("sim", "timestep", 0.05)))  # rate_hz 20
    assert cfg.sim.timestep == 0.05


def test_tls_endpoint_with_its_own_tls_settings_is_accepted(tmp_path):
    ep = "tls/127.0.0.1:7447#root_ca_certificate=/etc/ca.pem"
    load_config(_write(tmp_path, _set("zenoh", "connect", [ep])))


def test_two_certificates_with_one_common_name_are_refused(tmp_path, capsys):
    """Distinct files, same CN: the mTLS ACL could not tell the robots apart."""
    why = openssl_missing()
    if why:
        pytest.skip(why)
    a = make_certs(tmp_path / "a", ["r1", "ctl"])
    b = make_certs(tmp_path / "b", ["r1"])  # another r1, signed by another CA: same CN

    def mutate(d):
        d["zenoh"]["tls"] = {
            "certificate": str(a["ctl"][0]),
            "private_key": str(a["ctl"][1]),
            "root_ca": str(a["ca"][0]),
            "mtls": True,
        }
        d["zenoh"]["listen"] = ["tls/127.0.0.1:7447"]
        for r, who in zip(d["robots"], (a["r1"], b["r1"]), strict=False):
            r.update(zenoh_certificate=str(who[0]), zenoh_private_key=str(who[1]))

    path = _write(tmp_path, mutate)
    load_config(path)  # the loader reads no certificate (a robot's computer has only its own)
    _check_fails(path, "robots[1].zenoh_certificate", "common name 'r1'", capsys)


# --------------------------------------------------------------------------- every error at once


def _three_mistakes(d):
    d["fleet"]["rate_hzz"] = 20  # unknown key
    d["capture"]["population"] = "many"  # wrong type
    d["robots"][1]["radius"] = -1.0  # out of range, in a robot's entry


THREE = {
    "fleet.rate_hzz": "unknown key; did you mean 'rate_hz'?",
    "capture.population": "expected an integer, got 'many'",
    "robots[1].radius": "expected a value > 0, got -1.0",
}


def _check_lines(path: Path, capsys) -> tuple[list[str], dict]:
    assert main(["check", "--config", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert main(["check", "--config", str(path), "--json"]) == 2
    return captured.err.splitlines(), json.loads(capsys.readouterr().out)


def test_check_reports_three_independent_mistakes_in_one_run(tmp_path, capsys):
    path = _write(tmp_path, _three_mistakes)
    lines, out = _check_lines(path, capsys)
    for key, words in THREE.items():  # a line each, with the file and the key path
        assert [ln for ln in lines if f"fleet check: {path}: {key}: " in ln and words in ln], lines
    assert lines[-1] == f"fleet check: 3 errors in {path}"
    assert len(lines) == 4
    # --json: the former fields name the first error (document order), `errors` all of them
    assert out["ok"] is False and out["file"] == str(path)
    assert [e["key"] for e in out["errors"]] == [
        "fleet.rate_hzz",
        "robots[1].radius",
        "capture.population",
    ]
    assert out["path"] == "fleet.rate_hzz" and out["error"] == out["errors"][0]["message"]
    for e in out["errors"]:
        assert THREE[e["key"]] in e["message"]


def test_the_other_commands_still_stop_at_the_first_error(tmp_path, capsys):
    path = _write(tmp_path, _three_mistakes)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert info.value.path == "fleet.rate_hzz" and not hasattr(info.value, "errors")
    with pytest.raises(ConfigError) as info:
        load_config(path, all_errors=True)
    assert len(info.value.errors) == 3
    assert str(info.value) == str(info.value.errors[0])  # reads as the first one
    assert main(["run", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "fleet.rate_hzz" in err and "capture.population" not in err


def test_cross_field_rules_are_reported_together(tmp_path, capsys):
    def mutate(d):
        d["sim"]["timestep"] = 0.5  # longer than a tick at 20 Hz
        d["zenoh"]["listen"] = ["tcp/127.0.0.1:99999"]
        d["robots"][0]["start"] = [100.0, 1.0, 0.0]  # outside the room
        x, y, _ = d["robots"][2]["start"]
        d["robots"][4]["start"] = [x + 0.15, y, 0.0]  # on robots[2]

    lines, out = _check_lines(_write(tmp_path, mutate), capsys)
    keys = [e["key"] for e in out["errors"]]
    assert keys == ["sim.timestep", "zenoh.listen[0]", "robots[0].start", "robots[4].start"]
    assert lines[-1].endswith("4 errors in " + out["file"])


def test_rules_that_need_a_failed_one_are_not_run(tmp_path, capsys):
    """Inverted bounds: no robot, object or route is reported outside them (noise), but an
    independent rule (the timestep) still is."""

    def mutate(d):
        d["world"]["bounds"] = [[10.0, 10.0], [0.0, 0.0]]
        d["sim"]["timestep"] = 0.5

    _, out = _check_lines(_write(tmp_path, mutate), capsys)
    assert [e["key"] for e in out["errors"]] == ["world.bounds", "sim.timestep"]


def test_a_key_error_stops_before_the_cross_field_rules(tmp_path, capsys):
    def mutate(d):
        d["sim"]["timestep"] = 0.5  # a cross-field rule: not checked yet
        d["robots"][0]["start"] = "here"

    _, out = _check_lines(_write(tmp_path, mutate), capsys)
    assert [e["key"] for e in out["errors"]] == ["robots[0].start"]


def test_bad_toml_is_one_error(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("[fleet\nname = 1\n[capture]\npopulation = 'x'\n")
    lines, out = _check_lines(path, capsys)
    assert len(out["errors"]) == 1 and "not valid TOML" in out["error"]
    assert lines[-1] == f"fleet check: 1 error in {path}"


def test_a_huge_polygon_is_refused_before_anything_allocates_for_it(tmp_path, capsys):
    import math

    ring = [
        [5 + math.cos(a), 5 + math.sin(a)] for a in (2 * math.pi * k / 20000 for k in range(20000))
    ]
    path = _write(tmp_path, lambda d: d["object"].__setitem__("polygon", ring))
    _check_fails(path, "object.polygon", "20000 vertices: at most 1000", capsys)
    path = _write(tmp_path, lambda d: d["obstacles"][0].__setitem__("polygon", ring))
    _check_fails(path, "obstacles[0].polygon", "at most 1000", capsys)


@pytest.mark.parametrize(
    "user, char",
    [("op\u200balice", "U+200B"), ("\u0430lice", "U+0430"), ("ａlice", "U+FF41")],
)
def test_look_alike_identities_are_refused(tmp_path, capsys, user, char):
    def mutate(d):
        d["zenoh"]["operators"] = [user]

    _check_fails(_write(tmp_path, mutate), "zenoh.operators[0]", char, capsys)

    def robot(d):
        d["robots"][0].update(zenoh_user=user, zenoh_password="secret")

    _check_fails(_write(tmp_path, robot), "robots[0].zenoh_user", char, capsys)


def test_a_byte_order_mark_is_read_as_nothing(tmp_path):
    good = _write(tmp_path, lambda d: None)
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + good.read_bytes())
    assert load_config(str(bom)).robot_ids == load_config(str(good)).robot_ids
