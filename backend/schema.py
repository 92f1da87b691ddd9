"""JSON Schema of the file formats, generated from the models (never by hand)."""

from __future__ import annotations

from typing import Any

from .library import Library
from .model import Mission

SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def _schema(model: type, title: str, internal: set[str]) -> dict[str, Any]:
    s = model.model_json_schema(mode="validation")
    s["$schema"] = SCHEMA_DIALECT
    s["title"] = title
    for name in internal:  # server bookkeeping: allowed in files, not for authors
        s.get("properties", {}).get(name, {}).setdefault("readOnly", True)
    return s


def schemas() -> dict[str, dict[str, Any]]:
    return {
        "mission": _schema(
            Mission, "missionctl mission file", {"revision", "task_revs", "marker_revs", "report_seqs", "next_skill", "next_barrier"}
        ),
        "library": _schema(Library, "missionctl skill library file", set()),
    }
