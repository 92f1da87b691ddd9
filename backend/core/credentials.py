"""Credentials: account names, roles and password files, shared by the server
(its accounts file) and every client (ctl, console, sim, robots log in with them).

Password files are secrets: readable by their owner only (like ssh keys).
"""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Literal

Role = Literal["operator", "observer", "robot", "relay"]
USER_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"


class AccountsError(ValueError):
    """A problem with the accounts file or a password file; the text says what to do."""


def check_private(path: Path, what: str = "password file") -> None:
    """Refuse a secret that other users can read (as ssh does with keys)."""
    mode = path.stat().st_mode
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise AccountsError(
            f"{path}: this {what} is readable by other users; run: chmod 600 {path}"
        )


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
