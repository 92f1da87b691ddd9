"""`missionctl ctl`: every mission operation, scriptable against a running server.

The command (backend/cli/command.py): `args` is its command line, `build` the
operation each names, `session` runs one, `render` prints the outcome.
"""

from backend.cli.ctl.args import prepare_parser
from backend.cli.ctl.session import run

__all__ = ["prepare_parser", "run"]
