"""Fixtures for the console tests.

Offline tests build mission states with the real rules engine
(console_state.py) and inject them into the app as messages: no network, no
clocks, no animations, no cursor blink — deterministic snapshots. Timestamps
are shown in local time, so the tests pin TZ=UTC.

`async def` tests run in a fresh event loop with an overall timeout (no
pytest-asyncio needed), like tests/agent.
"""

from __future__ import annotations

import asyncio
import inspect
import os
import time

os.environ["TZ"] = "UTC"
time.tzset()

import pytest  # noqa: E402

TEST_TIMEOUT = 120.0


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    if not inspect.iscoroutinefunction(pyfuncitem.obj):
        return None
    kwargs = {name: pyfuncitem.funcargs[name] for name in pyfuncitem._fixtureinfo.argnames}
    asyncio.run(asyncio.wait_for(pyfuncitem.obj(**kwargs), TEST_TIMEOUT))
    return True


@pytest.fixture(autouse=True)
def _isolated_config(tmp_path, monkeypatch):
    """Never read the developer's own ~/.config/missionctl."""
    monkeypatch.setenv("MISSIONCTL_CONFIG", str(tmp_path / "no-config.toml"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))  # nor its own themes
