"""A save's file name from the mission's name, and a folder in its way, word
for word."""

from __future__ import annotations

from console.state.files import default_save_path, save_risks, shown_path


def test_the_file_is_named_after_the_mission_in_safe_characters(tmp_path):
    assert default_save_path("Ré-plan 2!", None, [], tmp_path) == tmp_path / "ré-plan_2_.yaml"
    assert default_save_path("", None, [], tmp_path) == tmp_path / "mission.yaml"
    assert default_save_path("a_b/c", None, [], tmp_path) == tmp_path / "a_b_c.yaml"


def test_a_folder_where_the_file_would_go_is_said(tmp_path):
    folder = tmp_path / "plan.yaml"
    folder.mkdir()
    assert save_risks(folder) == [f"{shown_path(folder)} is a folder"]
