"""Fixtures of tests/security: an accounts directory and a server using it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from .helpers import Accounts, SecureServer


@pytest.fixture
def accounts(tmp_path: Path) -> Accounts:
    return Accounts(tmp_path)


@pytest.fixture
def server(tmp_path: Path, accounts: Accounts) -> Iterator[SecureServer]:
    s = SecureServer(tmp_path, accounts)
    try:
        yield s
    finally:
        s.stop()
