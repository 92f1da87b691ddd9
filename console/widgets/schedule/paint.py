"""How the schedule panel draws one line of the view (its `render_line`):
the headers, each column's synchronized section, the divider, the plan — an
object the view owns (console/widgets/schedule/view.py). What a skill's row,
its progress line and a header look like: lines.py."""

from __future__ import annotations

from typing import Any

from rich.segment import Segment
from textual.strip import Strip

from backend.core.model import SkillInstance, Status
from console.state import link
from console.state.text import param_summary
from console.widgets.schedule.lines import (
    HEADER_H,
    HEADER_LINES,
    Column,
    Head,
    Styles,
    fit,
    progress_segments,
    row_tag,
    skill_segments,
    with_hidden_robots,
)


class Painter:
    def __init__(self, view: Any) -> None:
        self.view = view  # ScheduleView: columns, cursor, marks, drafts, scroll
        self.model = view.model
        self.summaries: dict[tuple[str, int], str] = {}  # (skill id, rev) -> parameter summary

    def line(self, y: int) -> Strip:
        v = self.view
        width = v.size.width
        st = v.styles_now()
        if not v.columns:
            return self._no_columns(y, width, st)
        x0 = int(v.scroll_x)
        x1 = x0 + width
        shown = self._shown(x0, x1)
        start = shown[0][1].x if shown else 0
        strip = Strip(self._row(shown, y, st)).crop_extend(x0 - start, x1 - start, st["base"])
        if y == HEADER_H - 1:  # on the rule under the headers, which hides nothing
            strip = with_hidden_robots(strip, v.hidden_robots(), x1 - x0, st["more"])
        return strip

    def _no_columns(self, y: int, width: int, st: Styles) -> Strip:
        """The panel before there is a column: why, on its second line."""
        if y != 1:
            return Strip.blank(width, st["base"])
        msg = (
            "  no mission yet — waiting for the server…"
            if self.model.mission is None
            else "  this mission has no robots"
        )
        return Strip([Segment(fit(msg, width), st["dim"])]).crop_extend(0, width, st["base"])

    def _shown(self, x0: int, x1: int) -> list[tuple[int, Column]]:
        """The columns (and their indexes) seen between x0 and x1: only those are drawn."""
        return [
            (ci, col)
            for ci, col in enumerate(self.view.columns)
            if col.x + col.width + 1 > x0 and col.x < x1
        ]

    def _row(self, shown: list[tuple[int, Column]], y: int, st: Styles) -> list[Segment]:
        """Screen row y across these columns, each followed by its divider."""
        if y == HEADER_H - 1:
            divider = Segment("┼", st["rule"])
        else:
            divider = Segment("│", st["divider"])
        line = int(self.view.scroll_y) + y - HEADER_H
        segs: list[Segment] = []
        for ci, col in shown:
            if y < HEADER_H:
                segs.extend(self._header_segments(col, y, st))
            else:
                segs.extend(self._content_segments(ci, col, line, st))
            segs.append(divider)
        return segs

    def _header_segments(self, col: Column, y: int, st: Styles) -> list[Segment]:
        v = self.view
        compact = self._compact(col)
        selected = y == HEADER_H - 1 and bool(v.columns) and v.columns[v.cursor_col] is col
        fresh = self.model.freshness(col.robot)
        return HEADER_LINES[y](Head(self.model, col, st, compact, selected, fresh))

    def _compact(self, col: Column) -> bool:
        """A static robot's narrow column (not expanded): hints and labels shorten."""
        return col.static and not self.view.expand_static

    def _content_segments(self, ci: int, col: Column, line: int, st: Styles) -> list[Segment]:
        v = self.view
        if line < 0 or line >= v.total_lines:
            return [Segment(" " * col.width, st["base"])]
        if line < v.sync_h:
            return self._sync_line(ci, col, line, st)
        if line == v.sync_h:
            label = "" if self._compact(col) else " plan "
            text = "┄┄" + label + "┄" * max(0, col.width - 2 - len(label))
            return [Segment(text[: col.width], st["divider"])]
        return self._plan_line(ci, col, line - v.sync_h - 1, st)

    def _sync_line(self, ci: int, col: Column, line: int, st: Styles) -> list[Segment]:
        """A line of the synchronized section: a skill's row or its progress line."""
        if line < len(col.sync):
            i, kind = col.sync[line]
            task = self.model.task(col.robot)
            if i < len(task):
                if kind == "row":
                    return self._skill_segments(ci, col, task[i], st)
                fresh = self.model.freshness(col.robot)
                return progress_segments(self.model, col, task[i], st, fresh)
        if line == 0 and not col.sync:
            return self._hint(col, "  nothing on robot", st)
        return [Segment(" " * col.width, st["base"])]

    def _plan_line(self, ci: int, col: Column, k: int, st: Styles) -> list[Segment]:
        """The k-th line under the divider: an unsynchronized skill's row."""
        if k < len(col.idle):
            i = col.idle[k]
            task = self.model.task(col.robot)
            if i < len(task):
                return self._skill_segments(ci, col, task[i], st)
        if k == 0 and not col.idle:
            return self._hint(col, "  empty plan", st)
        return [Segment(" " * col.width, st["base"])]

    def _hint(self, col: Column, text: str, st: Styles) -> list[Segment]:
        """What an empty section says ('  –' in a compact column)."""
        return [Segment(fit("  –" if self._compact(col) else text, col.width), st["dim"])]

    def _summary(self, s: SkillInstance) -> str:
        key = (s.id, s.rev)
        text = self.summaries.get(key)
        if text is None:
            text = param_summary(s, self.model.library)
            self.summaries[key] = text
        return text

    def _extra(self, col: Column, s: SkillInstance) -> str:
        """A synchronized skill's stage when its command is executing
        ('completed due 14:40'), else its parameters (a narrow static column: none)."""
        if self._compact(col):
            return ""
        stage = link.executing_stage(self.model, col.robot, s.id, self.model.clock)
        return stage or self._summary(s)

    def _skill_segments(self, ci: int, col: Column, s: SkillInstance, st: Styles) -> list[Segment]:
        v = self.view
        selected = ci == v.cursor_col and s.id == v.cursor_id
        stale = s.status != Status.IDLE and self.model.freshness(col.robot).stale
        c = self.model.uplinking(s.id)
        return skill_segments(
            s,
            col.width,
            st,
            marked=s.id in v.marks,
            draft=s.id in v.drafts,
            tag=row_tag(self.model, s),
            check=self.model.plan.mark(s.id),
            extra=self._extra(col, s),
            cursor=(st["cursor"] if v.has_focus else st["cursor-blur"]) if selected else None,
            stale=stale,
            uplink=link.staged_text(self.model, c, self.model.clock) if c is not None else "",
        )
