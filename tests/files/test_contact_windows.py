"""The deployment's contact windows file (backend.files.contact)."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from backend.files.contact import load_contact_windows
from backend.files.diagnostics import FileProblems

GOOD = """\
format: missionctl/contact-windows@1
robots:
  lru1:
    repeating: {open: 20m, every: 2h, first: 2026-11-28T12:00:00Z}
  lru2:
    passes:
      - {start: "2026-11-28T15:10:00+01:00", end: 2026-11-28T14:25:00Z}
"""


def _t(text: str) -> float:
    return datetime.fromisoformat(text).astimezone(UTC).timestamp()


def test_a_file_gives_each_robot_its_windows_on_the_wall_clock(tmp_path) -> None:
    f = tmp_path / "windows.yaml"
    f.write_text(GOOD)
    windows = load_contact_windows(f)
    rep = windows["lru1"].repeating
    assert rep is not None and (rep.open_s, rep.period_s) == (1200, 7200)
    assert rep.offset_s == _t("2026-11-28T12:00:00+00:00")
    [p] = windows["lru2"].passes
    assert (p.start, p.end) == (_t("2026-11-28T14:10:00+00:00"), _t("2026-11-28T14:25:00+00:00"))
    assert windows["lru2"].is_open(p.start) and not windows["lru2"].is_open(p.end)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        (
            "robots: {}\n",
            "1:1: format: this is not a contact windows file: start it with "
            "'format: missionctl/contact-windows@1'",
        ),
        (
            GOOD.replace("open: 20m", "open: 20 minutes"),
            ":4:",  # the line of lru1's window
        ),
        (GOOD.replace("open: 20m", "open: 3h"), "open (10800 s) must be shorter than every"),
        (GOOD.replace("2026-11-28T12:00:00Z", "2026-11-28T12:00:00"), ":4:"),  # no zone
        (GOOD.replace("14:25:00Z", "14:05:00Z"), ":7:"),
        (GOOD.replace("lru2:", "lru 2:"), "lru 2"),
        (GOOD + "  lru1: {}\n", "duplicate key"),
        (GOOD.replace("passes:", "pases:"), ":6:"),
    ],
)
def test_every_problem_says_where_and_what(tmp_path, text: str, said: str) -> None:
    f = tmp_path / "windows.yaml"
    f.write_text(text)
    with pytest.raises(FileProblems) as e:
        load_contact_windows(f)
    shown = str(e.value)
    assert shown.startswith(str(f) + ":") and said in shown, shown


def test_a_missing_file_is_said_plainly(tmp_path) -> None:
    with pytest.raises(FileProblems, match="no such file"):
        load_contact_windows(tmp_path / "none.yaml")


def test_the_documented_example_loads(tmp_path) -> None:
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "deployment.md").read_text()
    section = doc.split("## Contact windows", 1)[1]
    example = re.search(r"```yaml\n(.*?)```", section, re.S)
    assert example is not None
    f = tmp_path / "windows.yaml"
    f.write_text(example.group(1))
    assert set(load_contact_windows(f)) == {"lru1", "lru2"}
