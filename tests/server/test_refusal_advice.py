"""What a refusal of an operation the journal could not take tells the
operator to do, from the failure (tests/server/test_failure_paths.py makes
the disk full and the file locked for real; the others here)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from backend.server.journal import JournalError
from backend.server.refusals import JournalFailed

DB = Path("/var/missions/m.db")


@pytest.mark.parametrize(
    ("error", "advice"),
    [
        (
            JournalError(f"{DB} is not a missionctl journal"),
            "save the mission (`missionctl ctl save FILE`) and restart the server "
            "with --mission FILE and a new --db",
        ),
        (
            sqlite3.OperationalError("database is locked"),
            "another program holds the file locked: close it, then send it again",
        ),
        (
            sqlite3.OperationalError("database or disk is full"),
            "free disk space, then send it again",
        ),
        (
            sqlite3.OperationalError("attempt to write a readonly database"),
            "make the file writable, then send it again",
        ),
        (PermissionError("denied"), "make the file writable, then send it again"),
        (
            PermissionError("the file is locked"),
            "another program holds the file locked: close it, then send it again",
        ),
        (OSError("I/O error"), "check the disk and the file, then send it again"),
    ],
)
def test_the_advice_fits_the_failure(error: BaseException, advice: str) -> None:
    refusal = JournalFailed(DB, error, "the edit")
    assert str(refusal.message).endswith(f"the mission was not changed; {advice}")
