"""What a `missionctl` subcommand is: a module with these two functions.

backend's own subcommands are one module each (validate, schema, server,
certs, ctl); `main` adds their parsers in order and runs the one asked for.
Plug-ins (sim, console) keep their `register(subparsers)` hook instead.
"""

from __future__ import annotations

import argparse
from typing import Any, Protocol


class Command(Protocol):
    def prepare_parser(self, subparsers: Any) -> argparse.ArgumentParser:
        """Add this command's parser to `subparsers` (argparse's) and return it."""
        ...

    def run(self, args: argparse.Namespace) -> int:
        """Do it; the exit code (backend/exit_codes.py)."""
        ...
