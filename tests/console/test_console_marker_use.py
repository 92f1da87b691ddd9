"""What the map says of each marker's use: active (a queued or running skill
uses it), bound (idle skills only) or unused."""

from __future__ import annotations

from console_state import MARS_FLEET, fleet, mars_mid_execution

from console.state.markers import marker_use
from console.state.model import ConsoleModel


def test_a_marker_is_active_when_a_queued_or_running_skill_uses_it():
    b = mars_mid_execution()
    m = ConsoleModel()
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    # POI-A: lru1-3 (queued) before lru1-4 (idle): the busier use stays
    assert marker_use(m) == {
        "POI-A": "active",
        "POI-B": "unused",
        "ROI-east": "active",
        "ROI-north": "unused",  # only a finished skill's (ardea-2 failed)
        "WIFI-1": "unused",
    }
    assert marker_use(ConsoleModel()) == {}
