"""The lab access-control profile: zenoh's ``access_control`` block generated from the config.

Zenoh's ACL names its subjects by username (usrpwd), certificate common name, interface or zid,
and has no per-user wildcard ("robot X may put on robot/X/pose" cannot be written once for all
robots), so the per-robot rules are generated here from ``[[robots]]``. The listening hub (the
daemon) applies the block to every message crossing its links; its own session is not filtered.

The profile (``default_permission: deny``):

- everyone authenticated may subscribe, query and watch liveliness on any key, and receive
  declarations, replies and liveliness tokens;
- the controller's identity (``zenoh.user``) may do everything;
- operators (``zenoh.operators``) may put ``fleet/<fleet>/estop`` (stop and resume) and
  receive every publication (a viewer);
- robot ``X``'s agent (``robots[i].zenoh_user``) may put only ``robot/X/pose`` and
  ``robot/X/event``, declare only its own ``alive/robot/X`` token, answer only for its own
  latched e-stop (``estop/state/robot/X``), and is sent only
  ``robot/X/cmd`` and ``estop`` publications (it receives nothing of another robot's
  commands, whatever it subscribes to); with ``sim.world = "process"`` a ``sim`` robot's agent
  also puts ``sim/world/X/cmd`` and is sent ``sim/world/X/pose`` (its link to ``fleet world``,
  which runs as the controller's identity).

The e-stop: only operators and the controller's identity put ``estop`` (engage and resume);
a robot's own latch answers can only engage another holder's latch (``controller.latch``, a
check in code), and only the controller's identity answers on ``estop/state/hub/*`` and
``estop/state/controller/*`` (the answers a fresh holder may adopt, released too).

Blocked traffic is dropped silently (zenoh logs nothing per message). Pure: no I/O but
:func:`write_acl`. The command line is ``python -m controller.acl`` (controller/acl.py).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from controller import wire

if TYPE_CHECKING:
    from controller.config.sections import FleetConfig

READ = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
SERVE = ["declare_queryable", "reply", "liveliness_token"]
WRITE = ["put", "delete"]
BOTH = ["ingress", "egress"]


def _rule(rid: str, messages: list[str], flows: list[str], keys: list[str]) -> dict[str, Any]:
    return {
        "id": rid,
        "messages": messages,
        "flows": flows,
        "permission": "allow",
        "key_exprs": keys,
    }


def _block(rules: list, subjects: list, policies: list) -> dict[str, Any]:
    """An ``access_control`` block: default deny, these rules, subjects and policies."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def acl_for(config: FleetConfig) -> dict[str, Any]:
    """The ``access_control`` block of the lab profile for ``config`` (see the module doc).

    Needs ``zenoh.user`` and every robot's ``zenoh_user`` (the loader checks this first)."""
    fleet = config.fleet.name
    rules = [
        _rule("read", READ, BOTH, ["**"]),
        _rule("serve-out", SERVE, ["egress"], ["**"]),
        _rule("controller", READ + SERVE + WRITE, BOTH, ["**"]),
    ]
    subjects: list[dict[str, Any]] = [
        {"id": "everyone"},
        {"id": "controller", "usernames": [config.zenoh.user]},
    ]
    policies: list[dict[str, Any]] = [
        {"id": "everyone", "rules": ["read", "serve-out"], "subjects": ["everyone"]},
        {"id": "controller", "rules": ["controller"], "subjects": ["controller"]},
    ]
    if config.zenoh.operators:
        rules += [
            _rule("operator-estop", ["put"], ["ingress"], [wire.key("estop", fleet)]),
            _rule("operator-watch", ["put"], ["egress"], ["**"]),
        ]
        subjects.append({"id": "operators", "usernames": list(config.zenoh.operators)})
        policies.append(
            {
                "id": "operators",
                "rules": ["operator-estop", "operator-watch"],
                "subjects": ["operators"],
            }
        )
    for r in config.robots:
        own_in, own_token, own_out = f"robot-{r.id}-in", f"robot-{r.id}-token", f"robot-{r.id}-out"
        # what its driver needs beyond that (DriverSpec.acl): e.g. a sim robot of the shared
        # `fleet world` process puts the command it applies and is sent its samples
        world_in, world_out = r.spec.acl(config, r) if r.spec.acl else ([], [])
        rules += [
            _rule(
                own_in,
                ["put"],
                ["ingress"],
                [wire.key("robot_pose", fleet, id=r.id), wire.key("robot_event", fleet, id=r.id)]
                + world_in,
            ),
            _rule(
                own_token, ["liveliness_token"], ["ingress"], [wire.alive_key(fleet, "robot", r.id)]
            ),
            _rule(  # it answers for its own latched e-stop (fleet estop waits for that answer)
                f"robot-{r.id}-estop-state",
                ["declare_queryable", "reply"],
                ["ingress"],
                [wire.key("estop_state", fleet, role="robot", id=r.id)],
            ),
            _rule(
                own_out,
                ["put"],
                ["egress"],
                [wire.key("robot_cmd", fleet, id=r.id), wire.key("estop", fleet)] + world_out,
            ),
        ]
        subjects.append({"id": f"robot-{r.id}", "usernames": [r.zenoh_user]})
        policies.append(
            {
                "id": f"robot-{r.id}",
                "rules": [own_in, own_token, f"robot-{r.id}-estop-state", own_out],
                "subjects": [f"robot-{r.id}"],
            }
        )
    return _block(rules, subjects, policies)


def acl_json5(config: FleetConfig) -> str:
    """The block as JSON5 text (plain JSON, which is JSON5) with a header comment."""
    name = Path(config.source).name if config.source else "<config>"
    head = (
        f"// zenoh access_control block for fleet {config.fleet.name!r}, generated from {name}\n"
        "// by `python -m controller.acl CONFIG OUT` (controller/acl.py): do not edit by hand,\n"
        "// regenerate when robots or users change.\n"
    )
    return head + json.dumps(acl_for(config), indent=2) + "\n"


def write_acl(config: FleetConfig, path: str | Path) -> Path:
    """Write :func:`acl_json5` to ``path`` (for a standalone router or a review)."""
    p = Path(path)
    p.write_text(acl_json5(config), encoding="utf-8")
    return p


def site_acl(configs: list[FleetConfig], backbone: tuple[str, ...] = ()) -> dict[str, Any]:
    """The ``access_control`` block of a site's router (``fleet router``): each fleet's lab
    profile (:func:`acl_for`) side by side, every rule, subject and policy id prefixed with its
    fleet's name, so robot ``X`` of fleet A may do for fleet A's keys what the profile lets it
    and nothing on fleet B's (its rules name only ``fleet/A/...``; default deny).

    ``backbone``: usernames of the site's other routers that connect to this one (carrying
    daemons, operators and other hosts' traffic, which their own router admits): they may do
    everything, as a fleet's controller may. An operator of any fleet stays an operator of
    that fleet only."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for cfg in configs:
        block = acl_for(cfg)
        tag = f"{cfg.fleet.name}:"
        rules += [r | {"id": tag + r["id"]} for r in block["rules"]]
        subjects += [s | {"id": tag + s["id"]} for s in block["subjects"]]
        policies += [
            p
            | {
                "id": tag + p["id"],
                "rules": [tag + r for r in p["rules"]],
                "subjects": [tag + s for s in p["subjects"]],
            }
            for p in block["policies"]
        ]
    if backbone:
        rules.append(_rule("site:backbone", READ + SERVE + WRITE, BOTH, ["**"]))
        subjects.append({"id": "site:backbone", "usernames": list(backbone)})
        policies.append(
            {"id": "site:backbone", "rules": ["site:backbone"], "subjects": ["site:backbone"]}
        )
    return _block(rules, subjects, policies)
