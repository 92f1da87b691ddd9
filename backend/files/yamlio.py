"""YAML in and out, remembering where every value came from.

Loading keeps a map from field path to (line, column) so that every error
about a file can say `file:line:col` and the field path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

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
_BaseDumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class YamlSyntaxError(Exception):
    def __init__(self, line: int, col: int, message: str, path: Path = ()):
        super().__init__(message)
        self.line, self.col, self.message, self.path = line, col, message, path


def load(text: str) -> YamlDoc:
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return YamlDoc(None, {(): (1, 1)})
        doc = YamlDoc(None)
        _walk(loader, node, (), doc, set())
        doc.data = loader.construct_document(node)
        return doc
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        what = e.problem or str(e)
        if e.context and e.context not in what:
            what = f"{e.context}: {what}"
        raise YamlSyntaxError(line, col, f"YAML syntax error: {what}") from None
    except yaml.YAMLError as e:
        raise YamlSyntaxError(1, 1, f"YAML error: {e}") from None
    finally:
        loader.dispose()


def _pos(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _walk(loader: Any, node: yaml.Node, path: Path, doc: YamlDoc, above: set[int]) -> None:
    doc.marks.setdefault(path, _pos(node))
    if id(node) in above:  # an alias of one of its own ancestors
        line, col = _pos(node)
        raise YamlSyntaxError(
            line, col, "recursive YAML alias: a value cannot contain itself", path[:-1]
        )
    above = above | {id(node)}
    if isinstance(node, yaml.MappingNode):
        seen: set[Any] = set()
        for knode, vnode in node.value:
            key = (
                loader.construct_object(knode, deep=True)
                if isinstance(knode, yaml.ScalarNode)
                else None
            )
            # keys are named as written; a number key is not a list index
            key = key if isinstance(key, str) else str(key)
            sub = (*path, key)
            if key in seen:
                doc.duplicates.append((sub, *_pos(knode)))
            seen.add(key)
            # an entry is found at its key: that is the line a person looks at
            doc.marks[sub] = _pos(knode)
            _walk(loader, vnode, sub, doc, above)  # setdefault keeps the key's position
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _walk(loader, item, (*path, i), doc, above)


class _Dumper(_BaseDumper):
    pass


def _repr_dict(dumper: Any, data: dict) -> yaml.Node:
    # small mappings of scalars (poses, positions) read best on one line
    flow = (
        0 < len(data) <= 6
        and all(isinstance(v, int | float | str | bool) or v is None for v in data.values())
        and all(isinstance(k, str) and k in _FLOW_KEYS for k in data)
    )
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=flow)


_FLOW_KEYS = {"x", "y", "z", "roll", "pitch", "yaw"}


def _repr_str(dumper: Any, data: str) -> yaml.Node:
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
