"""Zenoh access-control rules made from a server's accounts (`acl_config`).

The router enforces them on every message, with everything not allowed denied:

- operator: read everything consoles read (the journal's history too), and
  submit operations — only on its own operation key `mc/v2/server/op/{user}`,
  so the server knows who sent each operation (the ACL is what authenticates it);
- observer: the same reads, no operation key at all;
- robot: only its robots' keys (register, downlink, telemetry, presence,
  uplink and world queryables, barrier tokens), world queries to any robot,
  presence of the server and of other robots; plus the simulator's feed;
- relay (a site's `missionctl router`): everything under the protocol's
  prefix, both ways: it carries its site's robots and consoles, whose own
  rules the relay enforces where they log in (`ground_cert_names`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.protocol.keys import PREFIX, Keys
from backend.protocol.mapfeed import KEY_MAP_DELTA, KEY_MAP_SNAPSHOT, KEY_STATUS, KEY_STATUS_LIVE
from backend.server.accounts import Account, Accounts

# what consoles read: (subscriptions, queries, liveliness)
_WATCH_SUBS = [
    Keys.EVENTS,
    Keys.FLEET,
    Keys.ALERTS,
    Keys.ALL_TELEMETRY,
    KEY_MAP_DELTA,
    KEY_STATUS_LIVE,
]
_WATCH_QUERIES = [Keys.STATE, Keys.HISTORY, Keys.PING, KEY_MAP_SNAPSHOT, KEY_STATUS]
_PRESENCE = [Keys.SERVER_ALIVE, Keys.ALL_ALIVE]


def _rule(rid: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {
        "id": rid,
        "permission": "allow",
        "flows": [flow],
        "messages": messages,
        "key_exprs": keys,
    }


def _watcher_rules(rid: str, user: str) -> list[dict[str, Any]]:
    queries = [*_WATCH_QUERIES, Keys.account(user)]
    return [
        _rule(f"{rid}-in", "ingress", ["declare_subscriber"], _WATCH_SUBS),
        _rule(f"{rid}-in-q", "ingress", ["query"], queries),
        _rule(
            f"{rid}-in-l",
            "ingress",
            ["declare_liveliness_subscriber", "liveliness_query"],
            _PRESENCE,
        ),
        _rule(f"{rid}-out", "egress", ["put", "delete"], _WATCH_SUBS),
        _rule(f"{rid}-out-r", "egress", ["reply"], queries),
        _rule(f"{rid}-out-l", "egress", ["liveliness_token"], _PRESENCE),
        # where the queryables are (queriers' matching status)
        _rule(f"{rid}-out-d", "egress", ["declare_queryable"], queries),
    ]


def _per_robot(robots: list[str], *keys: Callable[[str], str]) -> list[str]:
    """Each robot's keys, robot by robot."""
    return [key(r) for r in robots for key in keys]


def _robot_rules(rid: str, robots: list[str]) -> list[dict[str, Any]]:
    own_queryables = _per_robot(robots, Keys.uplink, Keys.world)
    server_queries = _per_robot(robots, Keys.register, Keys.downlink)
    worlds = [Keys.world("*")]
    own_tokens = _per_robot(robots, Keys.alive, lambda r: Keys.barrier_ready("*", r))
    telemetry = _per_robot(robots, Keys.telemetry)
    partners = [Keys.SERVER_ALIVE, Keys.ALL_ALIVE, Keys.barrier_ready("*", "*")]
    sim_pub = [KEY_MAP_DELTA, KEY_STATUS_LIVE]
    sim_serve = [KEY_MAP_SNAPSHOT, KEY_STATUS]
    return [
        _rule(f"{rid}-in-q", "ingress", ["query"], [*server_queries, *worlds]),
        _rule(
            f"{rid}-in-serve",
            "ingress",
            ["declare_queryable", "reply"],
            [*own_queryables, *sim_serve],
        ),
        _rule(f"{rid}-in-pub", "ingress", ["put"], [*telemetry, *sim_pub]),
        _rule(f"{rid}-in-tok", "ingress", ["liveliness_token"], own_tokens),
        _rule(
            f"{rid}-in-l",
            "ingress",
            ["declare_liveliness_subscriber", "liveliness_query"],
            partners,
        ),
        _rule(f"{rid}-out-q", "egress", ["query"], [*own_queryables, *sim_serve]),
        _rule(f"{rid}-out-r", "egress", ["reply"], [*server_queries, *worlds]),
        _rule(f"{rid}-out-l", "egress", ["liveliness_token"], partners),
        # a publisher sends only once it knows of a subscriber (write-side filtering);
        # consoles subscribe with a wildcard, which a rule key must include
        _rule(
            f"{rid}-out-d",
            "egress",
            ["declare_subscriber"],
            [Keys.ALL_TELEMETRY, *telemetry, *sim_pub],
        ),
        _rule(f"{rid}-out-dq", "egress", ["declare_queryable"], [*server_queries, *worlds]),
    ]


_EVERY_MESSAGE = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]


def _relay_rules(rid: str) -> list[dict[str, Any]]:
    everything = [f"{PREFIX}/**"]
    return [
        _rule(f"{rid}-in", "ingress", _EVERY_MESSAGE, everything),
        _rule(f"{rid}-out", "egress", _EVERY_MESSAGE, everything),
    ]


def _role_rules(rid: str, user: str, acc: Account) -> list[dict[str, Any]]:
    """The rules of an account's role: a relay's, a robot's, an observer's, and
    an operator's (an observer's, and its operations)."""
    if acc.role == "relay":
        return _relay_rules(rid)
    if acc.role == "robot":
        return _robot_rules(rid, acc.robots)
    own = _watcher_rules(rid, user)
    if acc.role == "operator":
        own += [
            _rule(f"{rid}-op-in", "ingress", ["query"], [Keys.op_as(user)]),
            _rule(f"{rid}-op-out", "egress", ["reply"], [Keys.op_as(user)]),
        ]
    return own


def acl_config(
    accounts: Accounts, *, cert_names: bool = False, ground_cert_names: list[str] | None = None
) -> dict[str, Any]:
    """Zenoh `access_control` for these accounts: deny by default, one
    subject per account (its user name; under mutual TLS also its
    certificate's common name), the rules of its role.

    `ground_cert_names` (a relay's): the link to the ground, told from the
    site's by the common name of the ground's TLS certificate, carries
    everything (the ground enforces the relay account's rules there)."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    if ground_cert_names:
        rules += _relay_rules("ground")
        subjects.append({"id": "ground-link", "cert_common_names": list(ground_cert_names)})
        policies.append(
            {
                "id": "ground-policy",
                "rules": ["ground-in", "ground-out"],
                "subjects": ["ground-link"],
            }
        )
    for n, (user, acc) in enumerate(sorted(accounts.table.accounts.items())):
        rid = f"a{n}"
        own = _role_rules(rid, user, acc)
        subject: dict[str, Any] = {"id": f"{rid}-{user}", "usernames": [user]}
        if cert_names:
            subject["cert_common_names"] = [user]
        rules += own
        subjects.append(subject)
        policies.append(
            {"id": f"{rid}-policy", "rules": [r["id"] for r in own], "subjects": [subject["id"]]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
