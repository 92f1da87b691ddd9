"""mypy, strict, on the packages pyproject's [tool.mypy] lists (core, protocol,
transport, files, agent, server, client, the simulator and the console's model), so the test
command checks the types too."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# may only grow: the console and the command line are still to come
CHECKED = {
    "backend/core",
    "backend/protocol",
    "backend/transport",
    "backend/files",
    "backend/agent",
    "backend/server",
    "backend/client",
    "sim",
}


def test_the_strict_check_covers_at_least_these_packages():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    assert config["strict"] is True
    assert CHECKED <= set(config["files"]), CHECKED - set(config["files"])


def test_the_listed_packages_type_check_strictly(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "mypy")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
