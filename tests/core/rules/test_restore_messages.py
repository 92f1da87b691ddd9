"""The refusal of an undo that would restore a barrier whose partner changed."""

from __future__ import annotations

import pytest

from backend.core.ops import AddBarrier, DeleteSkills, Undo
from backend.core.rules.engine import Refusal


def test_undoing_a_delete_refuses_a_barrier_whose_partner_joined_another(engine):
    bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1").value["barrier"]
    engine.submit(DeleteSkills(ids=["lru1-1"]), client="c1")
    assert bid not in engine.mission.barriers  # one robot left: dissolved
    engine.submit(AddBarrier(ids=["lru1-2", "lru2-1"]), client="c2")
    partner = engine.mission.find("lru2-1")[2]
    with pytest.raises(Refusal) as refused:
        engine.submit(Undo(), client="c1")
    assert refused.value.code == "barrier_invalid"
    assert str(refused.value) == (
        "cannot undo delete (dropped from your history): "
        f"cannot restore barrier {bid}: its partner {partner.display()} on lru2 has changed since"
    )
    assert "lru1-1" not in engine.mission.all_ids(), "a refused undo changes nothing"
