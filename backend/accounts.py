"""Accounts of a mission server and the Zenoh access-control rules made from them.

An accounts file (YAML) names each account's role and where its password is:

    format: missionctl/accounts@1
    accounts:
      ops:   {role: operator, password_file: secrets/ops.pw}
      watch: {role: observer, password_file: secrets/watch.pw}
      fleet: {role: robot, robots: [lru1, lru2], password_file: secrets/fleet.pw}

Zenoh's user/password authentication needs the plain passwords on the router
(its handshake is a challenge over the shared secret), so password files are
secrets: they must be readable by their owner only (like ssh keys). The
router reads them through a dictionary file that exists only while the router
session opens (`zenoh_dictionary`).

The roles become access-control rules (`acl_config`), enforced by the router
on every message, with everything not allowed denied:

- operator: read everything consoles read, and submit operations — only on
  its own operation key `mc/v1/server/op/{user}`, so the server knows who
  sent each operation (the ACL is what authenticates it);
- observer: the same reads, no operation key at all;
- robot: only its robots' keys (register, reports, telemetry, presence,
  command and world queryables, barrier tokens), world queries to any robot,
  presence of the server and of other robots; plus the simulator's feed.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError, field_validator

from .mapfeed import KEY_MAP_DELTA, KEY_MAP_SNAPSHOT, KEY_STATUS, KEY_STATUS_LIVE
from .model import Name, Strict
from .protocol import Keys

Role = Literal["operator", "observer", "robot"]
USER_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"


class AccountsError(ValueError):
    """A problem with the accounts file or a password file; the text says what to do."""


class Account(Strict):
    role: Role
    password_file: str = Field(description="file holding the password (one line); relative to the accounts file; mode 0600")
    robots: list[Name] = Field(default_factory=list, description="robot role: the robots this account may act as")

    @field_validator("robots")
    @classmethod
    def _unique(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("a robot is listed twice")
        return v


class AccountsFile(Strict):
    format: Literal["missionctl/accounts@1"] = "missionctl/accounts@1"
    accounts: dict[str, Account]

    @field_validator("accounts")
    @classmethod
    def _names(cls, v: dict[str, Account]) -> dict[str, Account]:
        import re

        for user, acc in v.items():
            if not re.match(USER_PATTERN, user):
                raise ValueError(f"account name {user!r}: use letters, digits, '.', '_', '-' (at most 64)")
            if acc.role == "robot" and not acc.robots:
                raise ValueError(f"account {user!r}: a robot account lists its robots (robots: [NAME, ...])")
            if acc.role != "robot" and acc.robots:
                raise ValueError(f"account {user!r}: only robot accounts list robots")
        if not v:
            raise ValueError("no accounts: nobody could log in")
        return v


class Accounts:
    """A loaded accounts file: roles and (in memory only) passwords."""

    def __init__(self, source: Path, table: AccountsFile, passwords: dict[str, str]):
        self.source = source
        self.table = table
        self._passwords = passwords

    def role(self, user: str) -> Role | None:
        acc = self.table.accounts.get(user)
        return acc.role if acc else None

    def robots(self, user: str) -> list[str]:
        acc = self.table.accounts.get(user)
        return list(acc.robots) if acc else []

    def __repr__(self) -> str:  # never the passwords
        return f"Accounts({self.source}, {sorted(self.table.accounts)})"


def check_private(path: Path, what: str = "password file") -> None:
    """Refuse a secret that other users can read (as ssh does with keys)."""
    mode = path.stat().st_mode
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise AccountsError(f"{path}: this {what} is readable by other users; run: chmod 600 {path}")


def read_password(path: str | Path) -> str:
    """The first line of a private password file (errors name the file and the fix)."""
    p = Path(path)
    try:
        check_private(p)
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise AccountsError(f"{p}: no such password file") from None
    except OSError as e:
        raise AccountsError(f"{p}: cannot read the password file: {e.strerror}") from None
    password = text.splitlines()[0].strip() if text.strip() else ""
    if not password:
        raise AccountsError(f"{p}: the password file is empty")
    if ":" in password:  # Zenoh's dictionary is user:password lines
        raise AccountsError(f"{p}: a password cannot contain ':'")
    return password


def load_accounts(path: str | Path) -> Accounts:
    from . import yamlio

    p = Path(path)
    try:
        doc = yamlio.load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise AccountsError(f"{p}: no such accounts file") from None
    except OSError as e:
        raise AccountsError(f"{p}: {e.strerror}") from None
    except yamlio.YamlSyntaxError as e:
        raise AccountsError(f"{p}:{e.line}:{e.col}: {e.message}") from None
    try:
        table = AccountsFile.model_validate(doc.data)
    except ValidationError as e:
        first = e.errors()[0]
        loc = tuple(first["loc"])
        line, col = doc.mark(loc)
        where = ".".join(str(x) for x in loc)
        raise AccountsError(f"{p}:{line}:{col}: {where + ': ' if where else ''}{first['msg']}") from None
    passwords = {
        user: read_password((p.parent / acc.password_file) if not Path(acc.password_file).is_absolute() else acc.password_file)
        for user, acc in table.accounts.items()
    }
    return Accounts(p, table, passwords)


@contextmanager
def zenoh_dictionary(accounts: Accounts) -> Iterator[str]:
    """A Zenoh `dictionary_file` (user:password lines) in a private temporary
    directory, removed on exit: Zenoh reads it when the router session opens."""
    with tempfile.TemporaryDirectory(prefix="missionctl-") as tmp:  # mode 0700
        path = Path(tmp) / "dictionary"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            for user, password in accounts._passwords.items():
                f.write(f"{user}:{password}\n")
        yield str(path)


# ---------------------------------------------------------------- access control

# what consoles read: (subscriptions, queries, liveliness)
_WATCH_SUBS = [Keys.EVENTS, Keys.FLEET, Keys.ALERTS, Keys.ALL_TELEMETRY, KEY_MAP_DELTA, KEY_STATUS_LIVE]
_WATCH_QUERIES = [Keys.STATE, Keys.PING, KEY_MAP_SNAPSHOT, KEY_STATUS]
_PRESENCE = [Keys.SERVER_ALIVE, Keys.ALL_ALIVE]


def _rule(rid: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rid, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": keys}


def _watcher_rules(rid: str, user: str) -> list[dict[str, Any]]:
    queries = [*_WATCH_QUERIES, Keys.account(user)]
    return [
        _rule(f"{rid}-in", "ingress", ["declare_subscriber"], _WATCH_SUBS),
        _rule(f"{rid}-in-q", "ingress", ["query"], queries),
        _rule(f"{rid}-in-l", "ingress", ["declare_liveliness_subscriber", "liveliness_query"], _PRESENCE),
        _rule(f"{rid}-out", "egress", ["put", "delete"], _WATCH_SUBS),
        _rule(f"{rid}-out-r", "egress", ["reply"], queries),
        _rule(f"{rid}-out-l", "egress", ["liveliness_token"], _PRESENCE),
        # where the queryables are (queriers' matching status)
        _rule(f"{rid}-out-d", "egress", ["declare_queryable"], queries),
    ]


def _robot_rules(rid: str, robots: list[str]) -> list[dict[str, Any]]:
    own_queryables = [k for r in robots for k in (Keys.command(r), Keys.world(r))]
    server_queries = [k for r in robots for k in (Keys.register(r), Keys.reports(r))]
    worlds = [Keys.world("*")]
    own_tokens = [k for r in robots for k in (Keys.alive(r), Keys.barrier_ready("*", r))]
    partners = [Keys.SERVER_ALIVE, Keys.ALL_ALIVE, Keys.barrier_ready("*", "*")]
    sim_pub = [KEY_MAP_DELTA, KEY_STATUS_LIVE]
    sim_serve = [KEY_MAP_SNAPSHOT, KEY_STATUS]
    return [
        _rule(f"{rid}-in-q", "ingress", ["query"], [*server_queries, *worlds]),
        _rule(f"{rid}-in-serve", "ingress", ["declare_queryable", "reply"], [*own_queryables, *sim_serve]),
        _rule(f"{rid}-in-pub", "ingress", ["put"], [*(Keys.telemetry(r) for r in robots), *sim_pub]),
        _rule(f"{rid}-in-tok", "ingress", ["liveliness_token"], own_tokens),
        _rule(f"{rid}-in-l", "ingress", ["declare_liveliness_subscriber", "liveliness_query"], partners),
        _rule(f"{rid}-out-q", "egress", ["query"], [*own_queryables, *sim_serve]),
        _rule(f"{rid}-out-r", "egress", ["reply"], [*server_queries, *worlds]),
        _rule(f"{rid}-out-l", "egress", ["liveliness_token"], partners),
        # a publisher sends only once it knows of a subscriber (write-side filtering);
        # consoles subscribe with a wildcard, which a rule key must include
        _rule(f"{rid}-out-d", "egress", ["declare_subscriber"],
              [Keys.ALL_TELEMETRY, *(Keys.telemetry(r) for r in robots), *sim_pub]),
        _rule(f"{rid}-out-dq", "egress", ["declare_queryable"], [*server_queries, *worlds]),
    ]


def acl_config(accounts: Accounts, *, cert_names: bool = False) -> dict[str, Any]:
    """Zenoh `access_control` for these accounts: deny by default, one
    subject per account (its user name; under mutual TLS also its
    certificate's common name), the rules of its role."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for n, (user, acc) in enumerate(sorted(accounts.table.accounts.items())):
        rid = f"a{n}"
        if acc.role == "robot":
            own = _robot_rules(rid, acc.robots)
        else:
            own = _watcher_rules(rid, user)
            if acc.role == "operator":
                own += [
                    _rule(f"{rid}-op-in", "ingress", ["query"], [Keys.op_as(user)]),
                    _rule(f"{rid}-op-out", "egress", ["reply"], [Keys.op_as(user)]),
                ]
        subject: dict[str, Any] = {"id": f"{rid}-{user}", "usernames": [user]}
        if cert_names:
            subject["cert_common_names"] = [user]
        rules += own
        subjects.append(subject)
        policies.append({"id": f"{rid}-policy", "rules": [r["id"] for r in own], "subjects": [subject["id"]]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}
