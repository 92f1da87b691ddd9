"""Parameters of type `marker` name a marker by value: renames follow them,
and a marker still named by a skill cannot be deleted."""

from backend.core.model import AreaMarker, Position
from backend.core.ops import AddSkill, MarkerAdd, MarkerDelete, MarkerRename

AREA = AreaMarker(area=[Position(x=0), Position(x=5), Position(x=5, y=5)])


def _pick_with_region(engine):
    engine.submit(MarkerAdd(name="ROI-1", marker=AREA))
    return engine.submit(
        AddSkill(
            robot="lru2", skill="pick_stone", params={"target": {"x": 1, "y": 1}, "region": "ROI-1"}
        )
    ).value["id"]


def test_rename_follows_marker_parameters(engine, skill):
    sid = _pick_with_region(engine)
    engine.submit(MarkerRename(name="ROI-1", new_name="ROI-2"))
    assert skill(engine, sid).params["region"] == "ROI-2"


def test_delete_refused_while_a_skill_names_the_marker(engine, refused):
    sid = _pick_with_region(engine)
    refused(
        engine, lambda: engine.submit(MarkerDelete(name="ROI-1")), "marker_in_use", sid, "region"
    )
