"""Accounts of a mission server: roles and passwords.

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

Each account's role becomes access-control rules: `backend.server.acl`.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError, field_validator

from backend.core.credentials import USER_PATTERN, AccountsError, Role, read_password
from backend.core.model import Name, Strict


class Account(Strict):
    role: Role
    password_file: str = Field(
        description="file holding the password (one line); relative to the accounts file; mode 0600"
    )
    robots: list[Name] = Field(
        default_factory=list, description="robot role: the robots this account may act as"
    )

    @field_validator("robots")
    @classmethod
    def _unique(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("a robot is listed twice")
        return v


def _account_problem(user: str, acc: Account) -> str | None:
    """What is wrong with an account's name or its robots (None: nothing)."""
    import re

    if not re.match(USER_PATTERN, user):
        return f"account name {user!r}: use letters, digits, '.', '_', '-' (at most 64)"
    if acc.role == "robot" and not acc.robots:
        return f"account {user!r}: a robot account lists its robots (robots: [NAME, ...])"
    if acc.role != "robot" and acc.robots:
        return f"account {user!r}: only robot accounts list robots"
    return None


class AccountsFile(Strict):
    format: Literal["missionctl/accounts@1"] = "missionctl/accounts@1"
    accounts: dict[str, Account]

    @field_validator("accounts")
    @classmethod
    def _names(cls, v: dict[str, Account]) -> dict[str, Account]:
        for user, acc in v.items():
            problem = _account_problem(user, acc)
            if problem is not None:
                raise ValueError(problem)
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


def load_accounts(path: str | Path) -> Accounts:
    p = Path(path)
    table = _table(p, _read(p))
    passwords = {
        user: read_password(_beside(p, acc.password_file)) for user, acc in table.accounts.items()
    }
    return Accounts(p, table, passwords)


def _read(p: Path) -> Any:
    """The accounts file's YAML document (AccountsError: unreadable, or not YAML)."""
    from backend.files import yamlio

    try:
        return yamlio.load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise AccountsError(f"{p}: no such accounts file") from None
    except OSError as e:
        raise AccountsError(f"{p}: {e.strerror}") from None
    except yamlio.YamlSyntaxError as e:
        raise AccountsError(f"{p}:{e.line}:{e.col}: {e.message}") from None


def _table(p: Path, doc: Any) -> AccountsFile:
    """The accounts it holds; AccountsError with the first problem's file:line:col."""
    try:
        return AccountsFile.model_validate(doc.data)
    except ValidationError as e:
        first = e.errors()[0]
        loc = tuple(first["loc"])
        line, col = doc.mark(loc)
        where = ".".join(str(x) for x in loc)
        raise AccountsError(
            f"{p}:{line}:{col}: {where + ': ' if where else ''}{first['msg']}"
        ) from None


def _beside(p: Path, password_file: str) -> str | Path:
    """A password file's path: relative ones from the accounts file's folder."""
    return password_file if Path(password_file).is_absolute() else p.parent / password_file


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
