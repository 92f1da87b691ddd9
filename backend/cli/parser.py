"""The argument parser of every `missionctl` command: a usage error exits 2."""

from __future__ import annotations

import argparse
import json
import sys

from backend.exit_codes import EXIT_BAD_INPUT


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error exits with EXIT_BAD_INPUT (2) and no traceback."""

    # `ctl --json`: a usage error is also a JSON object on stdout, like every
    # other failure of ctl (set from the command line before parsing it)
    json_errors = False

    def error(self, message: str):  # type: ignore[override]
        self.print_usage(sys.stderr)
        if self.json_errors:
            print(json.dumps({"ok": False, "code": "bad_input", "message": message}), flush=True)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")
