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
        scroll_x, scroll_y = int(v.scroll_x), int(v.scroll_y)
        st = v.styles_now()
        base = st["base"]
        if not v.columns:
            if y == 1:
                msg = (
                    "  no mission yet — waiting for the server…"
                    if self.model.mission is None
                    else "  this mission has no robots"
                )
                return Strip([Segment(fit(msg, width), st["dim"])]).crop_extend(0, width, base)
            return Strip.blank(width, base)
        x0, x1 = scroll_x, scroll_x + width
        segs: list[Segment] = []
        line = scroll_y + y - HEADER_H
        start: int | None = None  # x of the first visible column: only those are drawn
        for ci, col in enumerate(v.columns):
            if col.x + col.width + 1 <= x0 or col.x >= x1:
                continue
            if start is None:
                start = col.x
            if y < HEADER_H:
                segs.extend(self._header_segments(col, y, st))
            else:
                segs.extend(self._content_segments(ci, col, line, st))
            if y == HEADER_H - 1:
                segs.append(Segment("┼", st["rule"]))
            else:
                segs.append(Segment("│", st["divider"]))
        start = start or 0
        strip = Strip(segs).crop_extend(x0 - start, x1 - start, base)
        if y == HEADER_H - 1:  # on the rule under the headers, which hides nothing
            strip = with_hidden_robots(strip, v.hidden_robots(), x1 - x0, st["more"])
        return strip

    def _header_segments(self, col: Column, y: int, st: Styles) -> list[Segment]:
        v = self.view
        compact = col.static and not v.expand_static
        selected = y == HEADER_H - 1 and bool(v.columns) and v.columns[v.cursor_col] is col
        fresh = self.model.freshness(col.robot)
        return HEADER_LINES[y](Head(self.model, col, st, compact, selected, fresh))

    def _content_segments(self, ci: int, col: Column, line: int, st: Styles) -> list[Segment]:
        v = self.view
        w = col.width
        task = self.model.task(col.robot)
        if line < 0 or line >= v.total_lines:
            return [Segment(" " * w, st["base"])]
        if line < v.sync_h:
            if line < len(col.sync):
                i, kind = col.sync[line]
                if i < len(task):
                    s = task[i]
                    if kind == "row":
                        return self._skill_segments(ci, col, s, st)
                    return progress_segments(
                        self.model, col, s, st, self.model.freshness(col.robot)
                    )
            if line == 0 and not col.sync:
                hint = "  nothing on robot" if not col.static or v.expand_static else "  –"
                return [Segment(fit(hint, w), st["dim"])]
            return [Segment(" " * w, st["base"])]
        if line == v.sync_h:
            label = " plan " if not col.static or v.expand_static else ""
            text = "┄┄" + label + "┄" * max(0, w - 2 - len(label))
            return [Segment(text[:w], st["divider"])]
        k = line - v.sync_h - 1
        if k < len(col.idle):
            i = col.idle[k]
            if i < len(task):
                return self._skill_segments(ci, col, task[i], st)
        if k == 0 and not col.idle:
            hint = "  empty plan" if not col.static or v.expand_static else "  –"
            return [Segment(fit(hint, w), st["dim"])]
        return [Segment(" " * w, st["base"])]

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
        if col.static and not self.view.expand_static:
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
