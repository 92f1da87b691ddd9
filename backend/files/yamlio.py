"""YAML in and out, remembering where every value came from.

Loading keeps a map from field path to (line, column) so that every error
about a file can say `file:line:col` and the field path, and holds the file
to the limits of `backend.core.limits` (size, nesting, strings, lists,
mappings, alias expansion) before a document is built.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

from backend.core.limits import LIMITS, Limits, brief, echo, too_deep, too_long

Path = tuple[str | int, ...]


@dataclass
class YamlDoc:
    data: Any
    marks: dict[Path, tuple[int, int]] = field(default_factory=dict)  # 1-based line, col
    duplicates: list[tuple[Path, int, int]] = field(default_factory=list)

    def mark(self, path: Path) -> tuple[int, int]:
        """Position of the deepest known prefix of `path` (a missing field points
        at its parent)."""
        p = tuple(path)
        while p:
            if p in self.marks:
                return self.marks[p]
            p = p[:-1]
        return self.marks.get((), (1, 1))


# libyaml's parser is ~4x faster; positions are the same
_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_BaseDumper: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class YamlSyntaxError(Exception):
    """A file that cannot be read as YAML, or breaks a limit: the first
    problem, and in `problems` every one found, as (line, col, message, path)."""

    def __init__(
        self,
        line: int,
        col: int,
        message: str,
        path: Path = (),
        more: tuple[tuple[int, int, str, Path], ...] = (),
    ):
        super().__init__(message)
        self.line, self.col, self.message, self.path = line, col, message, path
        self.problems = [(line, col, message, path), *more]


def load(text: str, limits: Limits = LIMITS) -> YamlDoc:
    """The document in `text` with the position of every field, or
    YamlSyntaxError. Its size, nesting, strings, lists and mappings are
    checked first, on the parser's events (aliases counted at every use, so
    an "alias bomb" of a few hundred bytes is measured, never expanded)."""
    if len(text) > limits.file:  # characters: at least as many bytes
        raise YamlSyntaxError(1, 1, f"the file has more than the limit of {limits.file:,} bytes")
    doc = YamlDoc(None)
    loader = _Loader(text)
    try:
        _Scan(loader, doc, limits).run()
        loader.dispose()
        loader = _Loader(text)
        node = loader.get_single_node()
        if node is None:
            return YamlDoc(None, {(): (1, 1)})
        doc.data = loader.construct_document(node)
        return doc
    except yaml.MarkedYAMLError as e:
        raise _syntax_error(e) from None
    except yaml.YAMLError as e:
        raise YamlSyntaxError(1, 1, f"YAML error: {e}") from None
    finally:
        loader.dispose()


def _syntax_error(e: yaml.MarkedYAMLError) -> YamlSyntaxError:
    """The parser's error where it found it, its context first."""
    mark = e.problem_mark or e.context_mark
    line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
    what = e.problem or str(e)
    if e.context and e.context not in what:
        what = f"{e.context}: {what}"
    return YamlSyntaxError(line, col, f"YAML syntax error: {what}")


def _pos(mark: Any) -> tuple[int, int]:
    return mark.line + 1, mark.column + 1


_STR_TAG = "tag:yaml.org,2002:str"
_MAX_PROBLEMS = 20  # limit problems listed for one file before giving up on it


@dataclass
class _Frame:
    """An open mapping or sequence of the event stream."""

    path: Path
    is_map: bool
    anchor: str | None
    nodes_before: int  # nodes counted before it opened
    count: int = 0  # entries or items so far
    key: str | None = None  # the key of the entry whose value comes next (mappings)
    below: int = 0  # deepest nesting inside it (for an anchor's aliases)
    seen: set[str] = field(default_factory=set)


class _Scan:
    """One pass over the parser's events (no document is built): the limits,
    the position of every field and the duplicate keys. An alias adds the
    size and depth its anchor had, so an alias bomb costs what its text does.
    (Written for speed: a 10,000-skill file has 300,000 events.)"""

    def __init__(self, loader: Any, doc: YamlDoc, limits: Limits):
        self.loader, self.doc, self.limits = loader, doc, limits
        self.stack: list[_Frame] = []
        self.nodes = 0
        # anchor -> (nodes, depth, key text when a scalar)
        self.anchors: dict[str, tuple[int, int, str | None]] = {}
        self.problems: list[tuple[int, int, str, Path]] = []
        # first characters of plain scalars that may be something else than a string
        self._maybe_typed = set(loader.yaml_implicit_resolvers)

    def run(self) -> None:
        get = self.loader.get_event
        on = {
            yaml.ScalarEvent: self._scalar,
            yaml.MappingStartEvent: self._open,
            yaml.SequenceStartEvent: self._open,
            yaml.MappingEndEvent: self._close,
            yaml.SequenceEndEvent: self._close,
            yaml.AliasEvent: self._alias,
        }.get
        while True:
            e = get()
            handle = on(type(e))
            if handle is not None:
                handle(e)
            elif e is None or type(e) is yaml.StreamEndEvent:
                break
        if self.problems:
            first, *more = sorted(self.problems)
            raise YamlSyntaxError(first[0], first[1], first[2], first[3], tuple(more))

    # -- events ----------------------------------------------------------------------
    def _scalar(self, e: Any) -> None:
        stack = self.stack
        top = stack[-1] if stack else None
        at_key = top is not None and top.is_map and top.key is None
        if top is not None and at_key:
            path = self._key(top, self._key_text(e), e)
        else:
            path = self._place(top, e)
        if len(e.value) > self.limits.text:
            self._too_long(e, path, at_key)
        if e.anchor is not None:
            self.anchors[e.anchor] = (1, 0, self._key_text(e))
        self.nodes += 1
        if self.nodes > self.limits.yaml_nodes:
            self._too_many_nodes(e, path)

    def _too_long(self, e: Any, path: Path, at_key: bool) -> None:
        what = too_long(len(e.value), self.limits)
        shown = echo(e.value, self.limits)
        if at_key:  # said of the mapping: the path would hold the key
            self._problem(_pos(e.start_mark), path[:-1], f"a key of {what} ({shown})")
        else:
            self._problem(_pos(e.start_mark), path, f"{what} ({shown})")

    def _alias(self, e: Any) -> None:
        size, depth, text = self.anchors.get(e.anchor, (1, 0, None))
        self._not_within_itself(e)
        stack = self.stack
        top = stack[-1] if stack else None
        if top is not None and top.is_map and top.key is None:
            path = self._key(top, "None" if text is None else text, e)
        else:
            path = self._place(top, e)
        self.nodes += size
        if self.nodes > self.limits.yaml_nodes:
            self._too_many_nodes(e, path)
        if top is not None:
            self._nest(top, depth, e, path)

    def _not_within_itself(self, e: Any) -> None:
        """An alias inside the value its anchor names would be that value, endlessly."""
        stack = self.stack
        if any(f.anchor == e.anchor for f in stack):
            raise YamlSyntaxError(
                *_pos(e.start_mark),
                "recursive YAML alias: a value cannot contain itself",
                stack[-1].path,
            )

    def _nest(self, top: _Frame, depth: int, e: Any, path: Path) -> None:
        """An alias in `top` brings the nesting its anchor had (`depth`)."""
        top.below = max(top.below, depth)
        if len(self.stack) + depth > self.limits.depth:
            raise YamlSyntaxError(*_pos(e.start_mark), too_deep(self.limits.depth), brief(path))

    def _open(self, e: Any) -> None:
        top = self.stack[-1] if self.stack else None
        if top is not None and top.is_map and top.key is None:
            # a mapping or list as a key: the constructor refuses it later
            path = self._key(top, "None", e)
        else:
            path = self._place(top, e)
        if len(self.stack) >= self.limits.depth:
            raise YamlSyntaxError(*_pos(e.start_mark), too_deep(self.limits.depth), brief(path))
        self.nodes += 1
        if self.nodes > self.limits.yaml_nodes:
            self._too_many_nodes(e, path)
        is_map = type(e) is yaml.MappingStartEvent
        self.stack.append(_Frame(path, is_map, e.anchor, self.nodes - 1))

    def _close(self, e: Any) -> None:
        done = self.stack.pop()
        depth = done.below + 1
        if self.stack:
            top = self.stack[-1]
            if depth > top.below:
                top.below = depth
        if done.anchor is not None:
            self.anchors[done.anchor] = (self.nodes - done.nodes_before, depth, None)

    # -- where a node goes -----------------------------------------------------------
    def _key(self, top: _Frame, key: str, e: Any) -> Path:
        """Event `e` starts the key `key` of mapping `top`: the entry's path."""
        path = (*top.path, key)
        pos = _pos(e.start_mark)
        if key in top.seen:
            self.doc.duplicates.append((path, *pos))
        top.seen.add(key)
        # an entry is found at its key: that is the line a person looks at
        self.doc.marks[path] = pos
        top.key = key
        self._count(top)
        return path

    def _place(self, top: _Frame | None, e: Any) -> Path:
        """Event `e` starts a value (of the entry whose key came last, of a
        list, or the document): its path."""
        if top is None:
            path: Path = ()
        elif top.is_map:
            path = (*top.path, top.key if top.key is not None else "None")  # its key came first
            top.key = None
        else:
            path = (*top.path, top.count)
            self._count(top)
        self.doc.marks.setdefault(path, _pos(e.start_mark))
        return path

    def _count(self, top: _Frame) -> None:
        top.count += 1
        if top.count == self.limits.items + 1:  # said once, at the mapping or list
            what = "entries" if top.is_map else "items"
            message = f"more than the limit of {self.limits.items:,} {what}"
            self._problem(self.doc.mark(top.path), top.path, message)

    def _key_text(self, e: Any) -> str:
        """A scalar key as the document's data has it (`1` and `"1"` are both
        '1'; keys are named as written, a number key is not a list index)."""
        value = e.value
        if e.tag is None and e.implicit[0]:
            if value and value[0] not in self._maybe_typed:
                return str(value)
            tag = self.loader.resolve(yaml.ScalarNode, value, e.implicit)
        else:
            tag = e.tag or _STR_TAG
        return str(value) if tag == _STR_TAG else self._typed_key(tag, value)

    def _typed_key(self, tag: str, value: str) -> str:
        """A key of another type than a string, named as the data has it
        (`1` is '1', `true` 'True')."""
        try:
            typed = self.loader.construct_object(yaml.ScalarNode(tag, value))
        except yaml.YAMLError:
            return str(value)  # the constructor says what is wrong with it later
        return typed if isinstance(typed, str) else str(typed)

    def _too_many_nodes(self, e: Any, path: Path) -> None:
        raise YamlSyntaxError(
            *_pos(e.start_mark),
            f"the file expands to more than the limit of {self.limits.yaml_nodes:,} "
            "YAML nodes (an alias counts each time it is used)",
            brief(path),
        )

    def _problem(self, pos: tuple[int, int], path: Path, message: str) -> None:
        self.problems.append((*pos, message, brief(path)))
        if len(self.problems) >= _MAX_PROBLEMS:
            first, *more = sorted(self.problems)
            raise YamlSyntaxError(first[0], first[1], first[2], first[3], tuple(more))


class _Dumper(_BaseDumper):  # type: ignore[valid-type,misc]  # chosen at import: libyaml's if any
    pass


def _repr_dict(dumper: yaml.SafeDumper, data: dict[Any, Any]) -> yaml.Node:
    # small mappings of scalars (poses, positions) read best on one line
    flow = (
        0 < len(data) <= 6
        and all(isinstance(v, int | float | str | bool) or v is None for v in data.values())
        and all(isinstance(k, str) and k in _FLOW_KEYS for k in data)
    )
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=flow)


_FLOW_KEYS = {"x", "y", "z", "roll", "pitch", "yaw"}


def _repr_str(dumper: yaml.SafeDumper, data: str) -> yaml.Node:
    style = "|" if "\n" in data else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


_Dumper.add_representer(dict, _repr_dict)
_Dumper.add_representer(str, _repr_str)


def dump(data: Any) -> str:
    return yaml.dump(
        data,
        Dumper=_Dumper,
        sort_keys=False,
        allow_unicode=True,
        default_flow_style=False,
        width=100,
    )
