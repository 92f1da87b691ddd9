"""Shared by the bench scripts: the machine line and the section writer for
docs/performance.md (each script owns one "## ..." section and replaces only it)."""

from __future__ import annotations

import os
import platform
import re
from pathlib import Path

INTRO = """# Performance

Measured by the benchmark scripts in `bench/`; each section says how to
reproduce it, on which machine and when.
"""


def machine(*extra: str) -> str:
    """CPU model, cores, Python, `extra` (e.g. a library version), OS."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    parts = [
        cpu,
        f"{os.cpu_count()} cores",
        f"Python {platform.python_version()}",
        *extra,
        f"{platform.system()} {platform.release()}",
    ]
    return ", ".join(parts)


def write_section(path: Path, heading: str, text: str) -> None:
    """Replace the section starting with `heading` (e.g. "## Console") by
    `text`, or append it; the rest of the file stays as it is."""
    old = path.read_text(encoding="utf-8") if path.exists() else INTRO
    pattern = re.compile(rf"^{re.escape(heading)}\n.*?(?=^## |\Z)", re.S | re.M)
    if pattern.search(old):
        new = pattern.sub(lambda _m: text.rstrip("\n") + "\n\n", old, count=1)
    else:
        new = old.rstrip("\n") + "\n\n" + text
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(new.rstrip("\n") + "\n", encoding="utf-8")
