"""Accounts files and secrets handling, without a server."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from backend.core.credentials import AccountsError
from backend.server.accounts import load_accounts, zenoh_dictionary
from backend.transport import client_config, set_option
from backend.transport.login import Login


def _write(tmp: Path, body: str, password: str = "s3cret-pw", mode: int = 0o600) -> Path:
    pw = tmp / "a.pw"
    pw.write_text(password + "\n")
    os.chmod(pw, mode)
    f = tmp / "accounts.yaml"
    f.write_text("format: missionctl/accounts@1\naccounts:\n" + body)
    return f


def test_loads_roles_and_robots(tmp_path):
    acc = load_accounts(
        _write(
            tmp_path,
            "  ops: {role: operator, password_file: a.pw}\n"
            "  r: {role: robot, robots: [lru1], password_file: a.pw}\n",
        )
    )
    assert (
        acc.role("ops") == "operator" and acc.robots("r") == ["lru1"] and acc.role("nobody") is None
    )
    assert "s3cret-pw" not in repr(acc)


@pytest.mark.parametrize(
    "body, needle",
    [
        ("  r: {role: robot, password_file: a.pw}\n", "a robot account lists its robots"),
        (
            "  ops: {role: operator, robots: [lru1], password_file: a.pw}\n",
            "only robot accounts list robots",
        ),
        ("  'bad name': {role: operator, password_file: a.pw}\n", "account name 'bad name'"),
        (
            "  ops: {role: operator, password_file: missing.pw}\n",
            "missing.pw: no such password file",
        ),
        ("  ops: {role: operator}\n", "accounts.ops.password_file"),
    ],
)
def test_errors_say_what_and_where(tmp_path, body, needle):
    with pytest.raises(AccountsError) as e:
        load_accounts(_write(tmp_path, body))
    assert needle in str(e.value)
    assert str(tmp_path) in str(e.value)


def test_password_files_must_be_private_and_clean(tmp_path):
    with pytest.raises(AccountsError, match="chmod 600"):
        load_accounts(
            _write(tmp_path, "  ops: {role: operator, password_file: a.pw}\n", mode=0o640)
        )
    with pytest.raises(AccountsError, match="cannot contain ':'"):
        load_accounts(
            _write(tmp_path, "  ops: {role: operator, password_file: a.pw}\n", password="a:b")
        )


def test_the_zenoh_dictionary_is_private_and_removed(tmp_path):
    acc = load_accounts(_write(tmp_path, "  ops: {role: operator, password_file: a.pw}\n"))
    with zenoh_dictionary(acc) as path:
        p = Path(path)
        assert p.read_text() == "ops:s3cret-pw\n"
        assert p.stat().st_mode & 0o777 == 0o600 and p.parent.stat().st_mode & 0o777 == 0o700
    assert not p.exists() and not p.parent.exists()


def test_the_password_is_never_shown(tmp_path):
    login = Login(user="ops", password="s3cret-pw")
    assert "s3cret-pw" not in repr(login)
    cfg = client_config(["tcp/127.0.0.1:1"], extra=login.zenoh_options())
    with pytest.raises(ValueError) as e:  # an option Zenoh rejects: its value is not echoed
        set_option(cfg, "transport/auth/usrpwd/password", {"not": "a string"})
    assert "(hidden)" in str(e.value)
