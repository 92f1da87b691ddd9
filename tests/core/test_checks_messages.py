"""The library checks' sentences, word for word and in order (backend.core.checks)."""

from __future__ import annotations

from backend.core.checks import check_library
from backend.core.library import Library


def test_a_skill_naming_parameters_it_lacks_gets_every_sentence_in_order() -> None:
    lib = Library.model_validate(
        {
            "robot_types": {"rover": {"skills": ["survey"]}},
            "skills": {
                "survey": {
                    "params": {
                        "speed": {"type": "float", "default": 0.5},
                        "who": {"type": "str"},
                        "zone": {"type": "float"},
                    },
                    "talks_to": "who",
                    "duration": {
                        "goal_param": "speed",
                        "speed_param": "who",
                        "charge_param": "nothing",
                        "area_param": "zone",
                        "per_param_s": {"who": 1.0, "speed": 2.0},
                        "to_home": {"speed": 1.0, "back": True},
                    },
                    "energy": {"by_type": {"rover": {}, "drone": {}}},
                }
            },
        }
    )
    sk = ("skills", "survey")
    assert check_library(lib) == [
        (
            (*sk, "duration", "goal_param"),
            "'speed' is not a pose or position parameter of 'survey'",
        ),
        ((*sk, "talks_to"), "'who' is not a robot parameter of 'survey'"),
        ((*sk, "duration", "per_param_s", "who"), "'who' is not a numeric parameter of 'survey'"),
        ((*sk, "duration", "speed_param"), "'who' is not a numeric parameter of 'survey'"),
        ((*sk, "duration", "charge_param"), "'nothing' is not a numeric parameter of 'survey'"),
        ((*sk, "duration", "area_param"), "'zone' is not an area parameter of 'survey'"),
        ((*sk, "duration", "to_home", "back"), "'back' is not a parameter of 'survey'"),
        ((*sk, "energy", "by_type", "drone"), "unknown robot type 'drone' (library types: rover)"),
    ]


def test_a_skill_naming_fitting_parameters_has_no_problem() -> None:
    lib = Library.model_validate(
        {
            "robot_types": {"rover": {"skills": ["go"]}},
            "skills": {
                "go": {
                    "params": {
                        "goal": {"type": "pose"},
                        "speed": {"type": "float", "default": 0.5},
                        "zone": {"type": "area"},
                        "peer": {"type": "robot"},
                    },
                    "talks_to": "peer",
                    "duration": {
                        "goal_param": "goal",
                        "speed_param": "speed",
                        "area_param": "zone",
                        "per_param_s": {"speed": 1.0},
                        "to_home": {"speed": 1.0},
                    },
                    "energy": {"by_type": {"rover": {}}},
                }
            },
        }
    )
    assert check_library(lib) == []
