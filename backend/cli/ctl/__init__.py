"""`missionctl ctl`: every mission operation, scriptable against a running server.

The command (backend/cli/command.py): its parser and how it runs.
"""

from backend.cli.ctl.session import prepare_parser, run

__all__ = ["prepare_parser", "run"]
