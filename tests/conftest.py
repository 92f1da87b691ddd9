"""What every test folder shares: `async def` tests run here.

Each runs in a fresh event loop with `asyncio.run` (no pytest-asyncio needed)
and an overall timeout, so a hung test fails with a traceback of where it
waited instead of being killed by pytest-timeout.
"""

from __future__ import annotations

import asyncio
import inspect

import pytest

ASYNC_TEST_TIMEOUT = 120.0  # seconds; waits inside tests are on events, much shorter


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    if not inspect.iscoroutinefunction(pyfuncitem.obj):
        return None
    kwargs = {name: pyfuncitem.funcargs[name] for name in pyfuncitem._fixtureinfo.argnames}
    asyncio.run(asyncio.wait_for(pyfuncitem.obj(**kwargs), ASYNC_TEST_TIMEOUT))
    return True
