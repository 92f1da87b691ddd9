"""A path's completion offers hidden entries only when asked for."""

from __future__ import annotations

from console.state.files import completions


def test_hidden_entries_complete_only_after_a_dot(tmp_path):
    (tmp_path / ".plans").mkdir()
    (tmp_path / "plan.yaml").write_text("")
    (tmp_path / ".plan.yaml").write_text("")
    names = completions("", tmp_path, (".yaml",))
    assert names == ["./plan.yaml"]
    assert set(completions(".pl", tmp_path, (".yaml",))) == {".plans/", ".plan.yaml"}
