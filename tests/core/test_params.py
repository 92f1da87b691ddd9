"""The parameter-kind registry (backend.core.params): one entry per kind a
library may name, and each entry's parts agree with each other."""

import math
import typing

import pytest

from backend.core.model import AreaMarker, Pose, PoseMarker, Position, PositionMarker
from backend.core.params import (
    KINDS,
    ParamSpec,
    ParamType,
    StartContext,
    check_value,
    marker_value,
    normalize_value,
    starting_values,
    typed_params,
)

MARKERS = {
    "P": PoseMarker(kind="pose", pose={"x": 1, "y": 2}),
    "Q": PositionMarker(kind="position", position={"x": 3, "y": 4}),
    "A": AreaMarker(kind="area", area=[{"x": 0, "y": 0}, {"x": 1, "y": 0}, {"x": 1, "y": 1}]),
}


def spec(kind: str, **kw) -> ParamSpec:
    if kind == "enum":
        kw.setdefault("choices", ["low", "high"])
    return ParamSpec(type=kind, **kw)


def test_every_kind_a_library_may_name_has_an_entry():
    assert set(KINDS) == set(typing.get_args(ParamType))


@pytest.mark.parametrize("kind", sorted(typing.get_args(ParamType)))
def test_a_starting_value_passes_the_kinds_own_check(kind):
    ctx = StartContext(robot="lru1", markers=MARKERS, robots=("lru1", "lru2"))
    params, bindings = starting_values({"p": spec(kind)}, ctx)
    if "p" in bindings:  # bound: the marker must be able to give the value
        assert marker_value(spec(kind), MARKERS[bindings["p"]])[1] is None
    else:
        assert check_value(spec(kind), params["p"], markers=MARKERS, robots={"lru1", "lru2"}) == []


def test_starting_values_prefer_a_marker_for_an_area_and_another_robot():
    ctx = StartContext(robot="lru1", markers=MARKERS, robots=("lru1", "lru2"))
    params, bindings = starting_values({"a": spec("area"), "r": spec("robot")}, ctx)
    assert bindings == {"a": "A"} and params == {"r": "lru2"}


def test_a_parameter_with_a_default_gets_no_starting_value():
    assert starting_values({"n": spec("int", default=3)}, StartContext(robot="x")) == ({}, {})


def test_number_bounds_name_the_unit():
    s = spec("float", min=0.1, max=1.0, unit="m/s")
    assert check_value(s, 2, markers=None, robots=None) == [
        ((), "2 m/s is above the maximum 1 m/s")
    ]
    assert normalize_value(s, 1) == 1.0 and isinstance(normalize_value(s, 1), float)


def test_a_pose_marker_gives_a_position_and_an_area_marker_gives_no_pose():
    assert marker_value(spec("position"), MARKERS["P"]) == ({"x": 1.0, "y": 2.0, "z": 0.0}, None)
    assert marker_value(spec("pose"), MARKERS["A"]) == (None, "an area marker cannot give a pose")
    assert (
        marker_value(spec("int"), MARKERS["P"])[1] == "a int parameter cannot be bound to a marker"
    )


def test_handlers_get_values_typed_by_their_kind_never_by_their_shape():
    origin = {"x": 0.0, "y": 0.0, "z": 0.0}
    values = {"area": [origin] * 3, "at": origin, "raw": origin, "goal": {**origin, "yaw": 1.0}}
    kinds = {"area": "area", "at": "position", "raw": "dict", "goal": "pose", "partner": "robot"}
    assert typed_params(values, kinds) == {
        "area": [Position()] * 3,
        "at": Position(),
        "raw": origin,  # a dict parameter shaped like a position stays a dict
        "goal": Pose(yaw=1.0),
        "partner": None,  # an optional parameter left unset
    }
    # no kind sent (an older server): as the values came
    assert typed_params(values, {}) == values


# -- what a person reads and types: angles in degrees ---------------------------------


def test_angles_are_read_and_typed_in_degrees_and_stay_radians_on_the_wire():
    from backend.core.params import (
        angle_text,
        is_angle,
        parse_angle,
        value_from_text,
        value_text,
    )

    heading = ParamSpec(type="float", unit="rad", min=-math.pi, max=math.pi)
    assert is_angle(heading) and not is_angle(ParamSpec(type="float", unit="m"))
    # a bare number is in the unit shown (degrees); a unit says otherwise
    for typed, rad in [
        ("30", math.pi / 6),
        (30, math.pi / 6),
        ("30deg", math.pi / 6),
        ("30 °", math.pi / 6),
        ("-90 degrees", -math.pi / 2),
        ("0.52rad", 0.52),
        ("1e1deg", math.radians(10)),
    ]:
        value, problem = value_from_text(heading, typed)
        assert problem is None and value == pytest.approx(rad), typed
    # shown in degrees with the unit; what is shown, typed back, is the same angle
    assert value_text(heading, math.pi / 6) == "30°"
    for rad in (0.4, -2.5, 0.0, 1e-9, math.pi):
        shown = angle_text(rad)
        again, _ = parse_angle(shown)
        assert angle_text(again) == shown
    # bounds and errors in degrees too
    assert check_value(heading, 4.0, markers=None, robots=None)[0][1] == (
        "229.18° is above the maximum 180°"
    )
    for bad in ("east", "30 m", "", "nan", float("inf"), True, None):
        value, problem = parse_angle(bad)
        assert value is None and problem, bad


def test_pose_angles_in_text_and_from_text():
    from backend.core.params import value_from_text, value_text

    pose = ParamSpec(type="pose")
    assert value_text(pose, {"x": 1.0, "y": 2.0, "z": 0.0, "yaw": math.pi / 2}) == "(1,2 yaw=90°)"
    wire, problem = value_from_text(pose, {"x": 1, "y": 2, "yaw": 45, "pitch": "0.1rad"})
    assert problem is None
    assert wire["yaw"] == pytest.approx(math.pi / 4) and wire["pitch"] == 0.1 and wire["x"] == 1
    assert value_from_text(pose, {"yaw": "north"})[1].startswith("yaw: expected an angle")
    # not an angle: as typed
    assert value_from_text(ParamSpec(type="float", unit="m"), 30) == (30, None)
