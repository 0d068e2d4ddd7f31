"""Zenoh's own security through our config: user/password authentication, the lab ACL profile
(an agent cannot forge another robot's pose nor command another robot, a non-operator cannot
release the e-stop), TLS and mutual TLS with an ACL by certificate common name.

Every dropped message is followed by an allowed one on the same path; the allowed one arriving
is the handshake that proves the dropped one would have arrived before it (zenoh keeps order on
a link at one priority), so "nothing received" is checked without a sleep.
"""

from __future__ import annotations

import dataclasses
import json

import pytest

from controller import wire
from controller.config import ZenohIdentity, parse_config
from controller.io.bus import Bus, BusError
from tests.support.certs import make_certs, openssl_missing
from tests.support.config import base_config_dict
from tests.support.wait import wait_for

FLEET = "lab"


def _secure_config(tmp_path, port: int, **zenoh_extra):
    """The shipped config with three robots, each its own user, a password dictionary, the
    lab ACL profile and an operator."""
    users = {"ctl": "ctl-pw", "r1": "r1-pw", "r2": "r2-pw", "r3": "r3-pw", "op": "op-pw"}
    (tmp_path / "dict.txt").write_text("".join(f"{u}:{p}\n" for u, p in users.items()))
    for u, p in users.items():
        (tmp_path / f"{u}.pw").write_text(p + "\n")
    data = base_config_dict()
    data["robots"] = data["robots"][:3]
    for r in data["robots"]:
        r["zenoh_user"] = r["id"]
        r["zenoh_password_file"] = str(tmp_path / f"{r['id']}.pw")
    data["zenoh"] = {
        "listen": [f"tcp/127.0.0.1:{port}"],
        "user": "ctl",
        "password_file": str(tmp_path / "ctl.pw"),
        "auth_dictionary": str(tmp_path / "dict.txt"),
        "acl": "lab",
        "operators": ["op"],
        **zenoh_extra,
    }
    return parse_config(data, "test")


def _client(cfg, identity: ZenohIdentity, ep: str | None = None) -> Bus:
    return Bus(
        cfg.zenoh,
        cfg.fleet.name,
        mode="client",
        listen=[],
        connect=[ep] if ep else list(cfg.zenoh.listen),
        identity=identity,
    )


def _pose(seq: int, x: float = 1.0) -> wire.PoseMeasurement:
    return wire.PoseMeasurement(t=1.0, seq=seq, x=x, y=2.0, theta=0.0)


def test_wrong_or_missing_password_is_refused_at_connect(tmp_path, port):
    cfg = _secure_config(tmp_path, port)
    with Bus(cfg.zenoh, FLEET):
        wrong = dataclasses.replace(cfg.zenoh_identity("r1"), password="nope", password_file="")
        with pytest.raises(BusError):
            _client(cfg, wrong).close()
        anonymous = ZenohIdentity()
        with pytest.raises(BusError):
            _client(cfg, anonymous).close()
        # r1's password is r1's, not r2's
        stolen = dataclasses.replace(cfg.zenoh_identity("r2"), user="r1")
        with pytest.raises(BusError):
            _client(cfg, stolen).close()
        with _client(cfg, cfg.zenoh_identity("r1")):
            pass  # the right one connects


def test_lab_acl_agent_cannot_forge_poses_commands_or_release_the_estop(tmp_path, port):
    cfg = _secure_config(tmp_path, port)
    with (
        Bus(cfg.zenoh, FLEET) as hub,  # the daemon: controller identity, hub side, ACL
        _client(cfg, cfg.zenoh_identity("r1")) as r1,
        _client(cfg, cfg.zenoh_identity("r2")) as r2,
        _client(
            cfg,
            dataclasses.replace(
                cfg.zenoh_identity(), user="op", password="op-pw", password_file=""
            ),
        ) as op,  # fmt: skip
    ):
        poses = hub.subscribe_topic("robot_pose")  # every robot's
        estops = hub.subscribe_topic("estop")
        r2_cmds = r2.subscribe_topic("robot_cmd")  # r2 asks for every robot's commands

        own = r1.publisher("robot_pose", id="r1")
        forged = r1.publisher("robot_pose", id="r2")
        wait_for(lambda: own.matching() and forged.matching(), 10.0, "the hub's pose subscriber")

        # 1. r1 forges r2's pose, then publishes its own: only its own arrives
        forged.put(_pose(1, x=9.0))
        own.put(_pose(2))
        got = poses.get(timeout=5.0)
        assert got is not None and got.key == "fleet/lab/robot/r1/pose" and got.msg.seq == 2
        assert poses.drain() == []

        # 2. r2 receives its own commands only, whatever it subscribed to
        to_r1 = hub.publisher("robot_cmd", id="r1")
        to_r2 = hub.publisher("robot_cmd", id="r2")
        wait_for(to_r2.matching, 10.0, "r2's command subscriber")
        to_r1.put(wire.Twist2D(t=1.0, seq=10, vx=0.1))
        to_r2.put(wire.Twist2D(t=1.0, seq=11, vx=0.2))
        got = r2_cmds.get(timeout=5.0)
        assert got is not None and got.key == "fleet/lab/robot/r2/cmd" and got.msg.seq == 11
        assert r2_cmds.drain() == []

        # 3. r1 commands r2 and releases the e-stop; its next own pose proves both were dropped
        #    at the hub (same link, sent before), then the controller's marker reaches r2
        r1.put("robot_cmd", wire.Twist2D(t=1.0, seq=20, vx=0.4), id="r2")
        r1.put("estop", wire.EStop(t=1.0, seq=21, engaged=False, source="r1"))
        own.put(_pose(3))
        got = poses.get(timeout=5.0)
        assert got is not None and got.msg.seq == 3
        to_r2.put(wire.Twist2D(t=1.0, seq=22))
        got = r2_cmds.get(timeout=5.0)
        assert got is not None and got.msg.seq == 22, got  # not r1's forged 20
        assert r2_cmds.drain() == [] and estops.drain() == []

        # 4. an operator may release the e-stop
        op.put("estop", wire.EStop(t=1.0, seq=30, engaged=False, source="op"))
        got = estops.get(timeout=5.0)
        assert got is not None and got.msg.seq == 30 and got.msg.source == "op"


def test_tls_session_exchanges_messages(tmp_path, port):
    why = openssl_missing()
    if why:
        pytest.skip(why)
    certs = make_certs(tmp_path / "certs", ["hub"])
    ep = f"tls/127.0.0.1:{port}"
    data = base_config_dict()
    data["zenoh"] = {
        "listen": [ep],
        "tls": {
            "certificate": str(certs["hub"][0]),
            "private_key": str(certs["hub"][1]),
            "root_ca": str(certs["ca"][0]),
        },
    }
    cfg = parse_config(data, "test")
    with Bus(cfg.zenoh, FLEET) as hub, _client(cfg, ZenohIdentity()) as robot:
        inbox = hub.subscribe_topic("robot_pose", id="r1")
        pub = robot.publisher("robot_pose", id="r1")
        wait_for(pub.matching, 10.0, "the hub's subscriber over TLS")
        pub.put(_pose(5))
        got = inbox.get(timeout=5.0)
        assert got is not None and got.msg.seq == 5
        # the hub refuses plain TCP (transport/link/protocols = ["tls"])
        plain = dataclasses.replace(cfg.zenoh, tls=None, listen=())
        with pytest.raises(BusError):
            Bus(plain, FLEET, mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"]).close()


def test_mutual_tls_with_acl_by_certificate_common_name(tmp_path, port):
    why = openssl_missing()
    if why:
        pytest.skip(why)
    certs = make_certs(tmp_path / "certs", ["hub", "r1"])
    f = "fleet/lab"
    acl = {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {"id": "read", "messages": ["declare_subscriber", "declare_queryable", "query",
             "reply", "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
             "flows": ["ingress", "egress"], "permission": "allow", "key_exprs": ["**"]},
            {"id": "r1-pose", "messages": ["put"], "flows": ["ingress"], "permission": "allow",
             "key_exprs": [f"{f}/robot/r1/pose"]},
        ],
        "subjects": [{"id": "all"}, {"id": "r1", "cert_common_names": ["r1"]}],
        "policies": [{"rules": ["read"], "subjects": ["all"]},
                     {"rules": ["r1-pose"], "subjects": ["r1"]}],
    }  # fmt: skip
    (tmp_path / "acl.json5").write_text("// by common name\n" + json.dumps(acl))
    data = base_config_dict()
    data["robots"][0].update(
        zenoh_certificate=str(certs["r1"][0]), zenoh_private_key=str(certs["r1"][1])
    )
    data["zenoh"] = {
        "listen": [f"tls/127.0.0.1:{port}"],
        "tls": {
            "certificate": str(certs["hub"][0]),
            "private_key": str(certs["hub"][1]),
            "root_ca": str(certs["ca"][0]),
            "mtls": True,
        },
        "acl": str(tmp_path / "acl.json5"),
    }
    cfg = parse_config(data, "test")
    r1_ident = cfg.zenoh_identity("r1")  # its own certificate, common name "r1"
    with Bus(cfg.zenoh, FLEET) as hub:
        # without a certificate of our CA a client is refused
        with pytest.raises(BusError):
            no_cert = dataclasses.replace(cfg.zenoh, tls=dataclasses.replace(cfg.zenoh.tls,
                                          mtls=False), listen=())  # fmt: skip
            Bus(no_cert, FLEET, mode="client", listen=[], connect=list(cfg.zenoh.listen)).close()
        with _client(cfg, r1_ident) as r1:
            poses = hub.subscribe_topic("robot_pose")
            own = r1.publisher("robot_pose", id="r1")
            forged = r1.publisher("robot_pose", id="r2")
            wait_for(lambda: own.matching() and forged.matching(), 10.0, "the hub's subscriber")
            forged.put(_pose(1))
            own.put(_pose(2))
            got = poses.get(timeout=5.0)
            assert got is not None and got.key == f"{f}/robot/r1/pose" and got.msg.seq == 2
            assert poses.drain() == []
