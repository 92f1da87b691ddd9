"""Fixtures for the console tests.

Offline tests build mission states with the real rules engine
(console_state.py) and inject them into the app as messages: no network, no
clocks, no animations, no cursor blink — deterministic snapshots. Timestamps
are shown in local time, so the tests pin TZ=UTC.

`async def` tests run with the shared runner (tests/conftest.py).
"""

from __future__ import annotations

import os
import time

os.environ["TZ"] = "UTC"
time.tzset()

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _isolated_config(tmp_path, monkeypatch):
    """Never read the developer's own ~/.config/missionctl."""
    monkeypatch.setenv("MISSIONCTL_CONFIG", str(tmp_path / "no-config.toml"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))  # nor its own themes
