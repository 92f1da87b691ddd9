"""JSON Schema of the file formats, generated from the models (never by hand)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel

from backend.core.contact import ContactWindowsFile
from backend.core.library import Library
from backend.core.model import Mission

SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def _schema(model: type[BaseModel], title: str, internal: set[str]) -> dict[str, Any]:
    s = model.model_json_schema(mode="validation")
    _close_pattern_keys(s)
    s["$schema"] = SCHEMA_DIALECT
    s["title"] = title
    for name in internal:  # server bookkeeping: allowed in files, not for authors
        s.get("properties", {}).get(name, {}).setdefault("readOnly", True)
    return s


def _close_pattern_keys(node: Any) -> None:
    """Mappings keyed by names come out as patternProperties; without
    additionalProperties false, a key breaking the pattern would pass."""
    if isinstance(node, dict):
        if "patternProperties" in node:
            node.setdefault("additionalProperties", False)
        for v in node.values():
            _close_pattern_keys(v)
    elif isinstance(node, list):
        for v in node:
            _close_pattern_keys(v)


def schemas() -> dict[str, dict[str, Any]]:
    return {
        "mission": _schema(
            Mission,
            "missionctl mission file",
            {
                "revision",
                "task_revs",
                "marker_revs",
                "report_seqs",
                "uplink",
                "uplink_seqs",
                "next_command",
                "next_skill",
                "next_barrier",
            },
        ),
        "library": _schema(Library, "missionctl skill library file", set()),
        "contact-windows": _schema(
            ContactWindowsFile, "missionctl contact windows file (server --contact-windows)", set()
        ),
    }
