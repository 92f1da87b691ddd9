"""The contact state computed from windows (backend.core.contact)."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from backend.core.contact import (
    ContactPass,
    ContactWindows,
    RepeatingWindow,
    contact_at,
)

EVERY_2H = ContactWindows(repeating=RepeatingWindow(open_s=1200, period_s=7200))


def test_no_windows_is_always_in_contact() -> None:
    for windows in (None, ContactWindows()):
        c = contact_at(windows, 123456.0, present=True)
        assert (c.state, c.next_contact, c.closes) == ("in_contact", None, None)


def test_offline_wins_over_an_open_window() -> None:
    for windows in (None, EVERY_2H):
        c = contact_at(windows, 0.0, present=False)
        assert (c.state, c.next_contact, c.closes) == ("offline", None, None)


@pytest.mark.parametrize(
    ("t", "state", "next_contact", "closes"),
    [
        (0.0, "in_contact", None, 1200.0),  # a window opens at its start (included)
        (1199.5, "in_contact", None, 1200.0),
        (1200.0, "out_of_contact", 7200.0, None),  # and is closed at its end (excluded)
        (7199.0, "out_of_contact", 7200.0, None),
        (7200.0, "in_contact", None, 8400.0),
        (-1.0, "out_of_contact", 0.0, None),  # it repeats before its offset too
    ],
)
def test_repeating_window_boundaries(
    t: float, state: str, next_contact: float | None, closes: float | None
) -> None:
    c = contact_at(EVERY_2H, t, present=True)
    assert (c.state, c.next_contact, c.closes) == (state, next_contact, closes)


def test_offset_shifts_the_windows_like_the_simulator() -> None:
    w = ContactWindows(repeating=RepeatingWindow(open_s=600, period_s=3600, offset_s=1800))
    assert contact_at(w, 0.0, present=True).next_contact == 1800.0
    assert contact_at(w, 1800.0, present=True).closes == 2400.0


def test_passes_and_their_union_with_a_repeating_window() -> None:
    w = ContactWindows(
        repeating=RepeatingWindow(open_s=100, period_s=1000),
        passes=[ContactPass(start=50, end=300), ContactPass(start=5000, end=5100)],
    )
    # open from 0 (repeating) and on through the overlapping pass to 300
    assert contact_at(w, 10.0, present=True).closes == 300.0
    assert contact_at(w, 200.0, present=True).closes == 300.0
    assert contact_at(w, 300.0, present=True).next_contact == 1000.0
    only_passes = ContactWindows(passes=[ContactPass(start=5000, end=5100)])
    assert contact_at(only_passes, 4999.0, present=True).next_contact == 5000.0
    assert contact_at(only_passes, 5000.0, present=True).closes == 5100.0
    after = contact_at(only_passes, 5100.0, present=True)
    assert (after.state, after.next_contact) == ("out_of_contact", None)  # none ahead


def test_invalid_windows_are_refused_with_what_to_do() -> None:
    with pytest.raises(ValidationError, match="shorter than its period"):
        RepeatingWindow(open_s=7200, period_s=7200)
    with pytest.raises(ValidationError, match="end after it starts"):
        ContactPass(start=10, end=10)


def test_sim_time_reads_as_hours_minutes_seconds() -> None:
    from backend.core.contact import sim_time_text

    assert [sim_time_text(t) for t in (0, 1200, 7200.9, 90061)] == [
        "0:00:00",
        "0:20:00",
        "2:00:00",
        "25:01:01",
    ]
