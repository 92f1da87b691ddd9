"""The deployment's contact windows file (`missionctl server --contact-windows FILE`).

    format: missionctl/contact-windows@1
    robots:
      lru1:
        repeating: {open: 20m, every: 2h, first: 2026-11-28T12:00:00Z}
        passes:
          - {start: 2026-11-28T15:10:00Z, end: 2026-11-28T15:25:00Z}

Read like a mission file: held to the file limits, every problem located as
file:line:col with what to do, never a traceback.
"""

from __future__ import annotations

from pathlib import Path as FsPath

from pydantic import ValidationError

from backend.core.contact import CONTACT_FORMAT, ContactWindows, ContactWindowsFile
from backend.files.diagnostics import (
    FileProblems,
    duplicate_issues,
    located,
    pydantic_issues,
)
from backend.files.missions import read_yaml


def load_contact_windows(path: str | FsPath) -> dict[str, ContactWindows]:
    """Robot -> its windows on the wall clock (POSIX seconds); raises
    FileProblems saying every problem of the file."""
    file, doc = read_yaml(FsPath(path))
    issues = duplicate_issues(file, doc)
    if doc.data.get("format") != CONTACT_FORMAT:
        issues.append(
            located(
                file,
                doc,
                ("format",),
                f"this is not a contact windows file: start it with 'format: {CONTACT_FORMAT}'",
            )
        )
        raise FileProblems(issues)
    try:
        declared = ContactWindowsFile.model_validate(doc.data)
    except ValidationError as e:
        issues += pydantic_issues(file, doc, e)
        raise FileProblems(sorted(issues, key=lambda i: (i.line, i.col))) from None
    if issues:
        raise FileProblems(issues)
    return {robot: w.on_wall_clock() for robot, w in declared.robots.items()}
