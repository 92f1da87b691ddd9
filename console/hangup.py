"""Hanging up: SIGHUP (the SSH link dropped) or SIGTERM ends the console.

After a hang-up the terminal is gone: a write to it kills Textual's writer
thread, and its next writes then wait forever (seen with tmux kill-session).
So output goes to /dev/null from then on (`detach_terminal`), and a watchdog
ends the process, after the app's last hooks (e.g. the demo stopping its
children), should the clean exit still hang.
"""

from __future__ import annotations

import asyncio
import os
import signal
import threading
from collections.abc import Callable, Iterable
from typing import NoReturn

SIGNALS = (signal.SIGHUP, signal.SIGTERM)
HANG_UP_GRACE_S = 5.0  # after a hang-up, the longest a clean exit may take


def detach_terminal() -> None:
    """Point stdin/stdout/stderr at /dev/null (the terminal hung up)."""
    try:
        null = os.open(os.devnull, os.O_RDWR)
    except OSError:
        return
    for fd in (0, 1, 2):
        try:
            os.dup2(null, fd)
        except OSError:
            pass
    os.close(null)


def handle_signals(loop: asyncio.AbstractEventLoop, handler: Callable[[int], object]) -> None:
    """`handler(signal)` on SIGHUP and SIGTERM (where the loop can)."""
    for sig in SIGNALS:
        try:
            loop.add_signal_handler(sig, handler, sig)
        except (NotImplementedError, RuntimeError, ValueError):
            pass


def unhandle_signals(loop: asyncio.AbstractEventLoop) -> None:
    for sig in SIGNALS:
        try:
            loop.remove_signal_handler(sig)
        except (NotImplementedError, RuntimeError, ValueError):
            pass


def start_watchdog(expire: Callable[[], object], grace: float = HANG_UP_GRACE_S) -> None:
    """`expire()` in `grace` seconds, on a daemon thread (the loop may be stuck)."""
    watchdog = threading.Timer(grace, expire)
    watchdog.daemon = True
    watchdog.start()


def force_exit(hooks: Iterable[Callable[[], object]], code: int) -> NoReturn:
    """Run the last hooks (whatever they raise), then end the process now."""
    for hook in hooks:
        try:
            hook()
        except Exception:
            pass
    os._exit(code)
