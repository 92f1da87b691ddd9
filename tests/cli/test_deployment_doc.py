"""docs/deployment.md's commands are commands missionctl takes: every
`missionctl …` line of its sh blocks parses with the real parser (its options
exist and fit together), so the walk-through cannot drift from the CLI.
The deployment itself is run by tests/transport/test_relay.py."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from backend.cli.main import build_parser

DOC = Path(__file__).resolve().parents[2] / "docs" / "deployment.md"


def _commands() -> list[list[str]]:
    text = DOC.read_text(encoding="utf-8")
    out = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, re.M | re.S):
        joined = block.replace("\\\n", " ")
        for line in joined.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("missionctl "):
                out.append(shlex.split(line)[1:])
    return out


COMMANDS = _commands()


def test_the_walk_through_has_its_commands():
    assert {argv[0] for argv in COMMANDS} >= {"server", "router", "sim", "console", "certs"}
    assert any("--link-delay-hint" in argv for argv in COMMANDS if argv[0] == "router")


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda argv: " ".join(argv)[:60])
def test_each_command_parses(argv):
    args = build_parser().parse_args(argv)
    assert args.func is not None
    if "--link-delay-hint" in argv:
        assert args.link_delay_hint > 0
