"""The two ways ctl refuses its own input (exit 2, nothing sent)."""

from __future__ import annotations

from typing import Any


class UsageError(Exception):
    """Bad input on the command line: exit 2, nothing sent."""


class FileInvalid(Exception):
    """A mission file that does not validate: exit 2 with every issue."""

    def __init__(self, file: str, issues: list[Any]):
        super().__init__(f"{file} is not a valid mission ({len(issues)} problem(s))")
        self.file = file
        self.issues = issues
