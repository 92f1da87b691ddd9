"""Client-side connection options, shared by ctl, console, sim and robots.

    --user U --password-file F      log in (the password is read from F, never
                                    taken from the command line)
    --ca FILE                       trust this CA for tls/ endpoints
    --cert FILE --key FILE          client certificate (mutual TLS)
    --link-delay-hint D             the link's expected one-way delay (6s, 1.3):
                                    every timeout follows from it
                                    (backend.transport.timeouts)

`Login.zenoh_options()` turns them into Zenoh client config options. The
password exists only in memory and in the Zenoh config; `repr(Login)` hides it.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from backend.core.credentials import USER_PATTERN, AccountsError, read_password
from backend.core.durations import duration_s
from backend.transport import timeouts


@dataclass(frozen=True)
class Login:
    user: str = ""
    password: str = field(default="", repr=False)
    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    # seconds, one way: the Zenoh timeouts here, the protocol's query
    # timeouts where the client makes its queries (0: a LAN's defaults)
    link_delay_hint: float = 0.0

    @property
    def logged_in(self) -> bool:
        return bool(self.user and self.password)

    def zenoh_options(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.logged_in:
            out["transport/auth/usrpwd/user"] = self.user
            out["transport/auth/usrpwd/password"] = self.password
        if self.ca:
            out["transport/link/tls/root_ca_certificate"] = self.ca
        if self.cert and self.key:
            out["transport/link/tls/enable_mtls"] = True
            out["transport/link/tls/connect_certificate"] = self.cert
            out["transport/link/tls/connect_private_key"] = self.key
        out.update(timeouts.zenoh_options(self.link_delay_hint))
        return out


def delay_hint(text: str) -> float:
    """argparse's `type` for --link-delay-hint: 6s, 1.3, 500ms, 0."""
    seconds = duration_s(text)
    if seconds is None:
        raise argparse.ArgumentTypeError(
            f"not a delay: {text!r} (examples: 6s, 1.3, 500ms, 0 for a LAN)"
        )
    return seconds


DELAY_HINT_HELP = (
    "the link's expected one-way delay (e.g. 1.3s to the Moon, 6s through a relay pass; "
    "default 0: a LAN). Zenoh's open/accept timeouts, lease and keep-alive and the "
    "protocol's query timeouts follow from it (docs/deployment.md); give every process "
    "of a deployment the same"
)


def add_delay_hint_argument(p: argparse.ArgumentParser | Any, *, suppress: bool = False) -> None:
    p.add_argument(
        "--link-delay-hint",
        type=delay_hint,
        metavar="D",
        default=argparse.SUPPRESS if suppress else 0.0,
        help=DELAY_HINT_HELP,
    )


def add_login_arguments(
    p: argparse.ArgumentParser | Any, *, user_help: str | None = None, suppress: bool = False
) -> None:
    """--user, --password-file, --ca, --cert, --key on a parser or argument group.
    `suppress`: leave unset options out of the namespace (sub-command overrides)."""
    d = (lambda v: argparse.SUPPRESS) if suppress else (lambda v: v)
    p.add_argument(
        "--user",
        metavar="USER",
        default=d(""),
        help=user_help or "account to log in as (with --password-file)",
    )
    p.add_argument(
        "--password-file",
        metavar="FILE",
        default=d(None),
        help="file holding the account's password (mode 0600); "
        "never give a password on the command line",
    )
    p.add_argument(
        "--ca",
        metavar="FILE",
        default=d(None),
        help="CA certificate that signed the server's (tls/ endpoints)",
    )
    p.add_argument(
        "--cert",
        metavar="FILE",
        default=d(None),
        help="client certificate for mutual TLS (with --key)",
    )
    p.add_argument("--key", metavar="FILE", default=d(None), help="private key of --cert")
    add_delay_hint_argument(p, suppress=suppress)


def login_from_args(args: argparse.Namespace) -> Login:
    """Read the password file; raises `AccountsError` (a sentence naming the file) on problems."""
    user = getattr(args, "user", "") or ""
    password_file = getattr(args, "password_file", None)
    ca, cert, key = (getattr(args, name, None) for name in ("ca", "cert", "key"))
    _check_login(user, password_file, cert, key)
    _check_files((("--ca", ca), ("--cert", cert), ("--key", key)))
    return Login(
        user=user,
        password=read_password(password_file) if password_file else "",
        ca=_absolute(ca),
        cert=_absolute(cert),
        key=_absolute(key),
        link_delay_hint=float(getattr(args, "link_delay_hint", 0.0) or 0.0),
    )


def _check_login(user: str, password_file: str | None, cert: str | None, key: str | None) -> None:
    """A password file with the account it is for; a certificate with its key."""
    if password_file and not user:
        raise AccountsError("--password-file needs --user (the account it belongs to)")
    if bool(cert) != bool(key):
        raise AccountsError("--cert and --key go together (mutual TLS)")
    if password_file and not re.match(USER_PATTERN, user):
        raise AccountsError(f"--user {user!r}: account names use letters, digits, '.', '_', '-'")


def _check_files(files: tuple[tuple[str, str | None], ...]) -> None:
    """Each (option, file) given names a file."""
    for opt, path in files:
        if path and not Path(path).is_file():
            raise AccountsError(f"{opt} {path}: no such file")


def _absolute(path: str | None) -> str | None:
    # Zenoh reads the files later, maybe after a change of directory
    return str(Path(path).resolve()) if path else None
