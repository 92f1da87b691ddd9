"""Fixtures for the console tests.

Offline tests build mission states with the real rules engine
(console_state.py) and inject them into the app as messages: no network, no
clocks, no animations, no cursor blink — deterministic snapshots. Timestamps
are shown in local time, so the tests pin TZ=UTC.

`async def` tests run with the shared runner (tests/conftest.py).
"""

from __future__ import annotations

import gc
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


# -- `missionctl review` (test_console_review*.py) --------------------------------------------


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """A recorded mission (tests/files/recorded.py): journal and telemetry archive."""
    from tests.files.recorded import record_mission

    return record_mission(tmp_path_factory.mktemp("review"))


@pytest.fixture
def replay_of(recorded):
    """`make_replay(model)` for a ReviewApp: the recording, opened read-only."""
    from backend.files.missions import load_library
    from backend.files.record.journal import JournalReader
    from backend.protocol.archive import ArchiveReader, archive_path
    from console.state.replay import Replay

    with JournalReader(recorded.db) as j, ArchiveReader(archive_path(recorded.db)) as a:
        library = load_library(j.library)
        yield lambda model: Replay(model, j, library, a)
    gc.unfreeze()  # what a seek froze (Replay.release), for the tests after
