"""ctl's command-line values: `--param NAME=VALUE`, names, --pose/--position/--area.

Angles are typed in degrees, as ctl prints them: a bare number is degrees,
`30deg` and `0.52rad` say their unit (backend.core.params.parse_angle); the
wire keeps radians. `--pose`'s roll, pitch and yaw are angles; a `--param`
is one when its spec says so (`param_value`, once the library is known).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from datetime import date, datetime
from typing import Any

from backend.cli.ctl.errors import UsageError
from backend.core.durations import duration_s
from backend.core.params import (
    ANGLE_FIELDS,
    POSE_FIELDS,
    POSITION_FIELDS,
    ParamSpec,
    parse_angle,
    value_from_text,
)

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_\-]*$")  # model.NAME_PATTERN (kept light to import)


def parse_duration(text: str) -> float:
    """'30m', '2h', '90s', '500ms', '1.5' (seconds) -> seconds; 'never' -> 0.
    argparse's `type` (a bad one is an ArgumentTypeError: usage, exit 2)."""
    import argparse

    if text.strip().lower() in ("never", "none", "off"):
        return 0.0
    seconds = duration_s(text)
    if seconds is None:
        raise argparse.ArgumentTypeError(
            f"not a duration: {text!r} (examples: 30m, 2h, 90s, 500ms, never)"
        )
    return seconds


@dataclass(frozen=True)
class AtMarker:
    """`NAME=@MARKER` on the command line."""

    name: str


def check_name(value: str, what: str) -> str:
    if not _NAME_RE.match(value or ""):
        raise UsageError(
            f"{what}: {value!r} is not a valid name "
            "(letters, digits, '_' and '-', starting with a letter)"
        )
    return value


def _plain(value: Any, where: str) -> Any:
    """YAML values as JSON carries them: dates become strings, NaN/inf refused."""
    if isinstance(value, float) and not math.isfinite(value):
        raise UsageError(f"{where}: {value} is not a finite number")
    if isinstance(value, datetime | date):
        return value.isoformat()
    if isinstance(value, dict):
        return {str(k): _plain(v, where) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v, where) for v in value]
    return value


def parse_param(text: str) -> tuple[str, Any]:
    """`NAME=VALUE` -> (name, value); VALUE is YAML, `@M` a AtMarker."""
    from backend.core.limits import echo, show_path
    from backend.files import yamlio

    name, sep, raw = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise UsageError(
            f"--param {text!r}: expected NAME=VALUE (e.g. --param speed=0.5 or --param goal=@POI-A)"
        )
    if not _NAME_RE.match(name):
        raise UsageError(f"--param {text!r}: {name!r} is not a parameter name")
    stripped = raw.strip()
    if stripped.startswith("@"):
        return name, AtMarker(check_name(stripped[1:], f"--param {name}=@MARKER"))
    try:
        value = yamlio.load(raw).data  # within the file limits: an alias bomb is refused here
    except yamlio.YamlSyntaxError as e:
        if not e.message.startswith("YAML"):  # over a limit
            where = show_path(e.path)
            raise UsageError(
                f"--param {name}: {f'{where}: ' if where else ''}{e.message}"
            ) from None
        why = e.message.removeprefix("YAML syntax error: ").splitlines()[0]
        hint = ""
        if stripped[:1] in "{[":
            hint = f"; quote the whole argument for the shell: --param '{name}={{x: 3, y: 4}}'"
        elif ":" in stripped:
            hint = f"; write a mapping in braces: --param '{name}={{x: 3, y: 4}}'"
        raise UsageError(
            f"--param {name}: {echo(raw)} is not a valid YAML value ({why}){hint}"
        ) from None
    if isinstance(value, dict | list) and stripped[:1] not in "{[":
        raise UsageError(
            f"--param {name}: {echo(raw)} reads as a YAML block "
            f"{'mapping' if isinstance(value, dict) else 'list'}; write mappings in braces "
            "({x: 3, y: 4}) and lists in brackets ([a, b]), quoted for the shell"
        )
    if isinstance(value, str) and value.startswith("@") and len(value) > 1:
        return name, AtMarker(check_name(value[1:], f"--param {name}=@MARKER"))
    return name, _plain(value, f"--param {name}")


def param_value(name: str, value: Any, spec: ParamSpec | None) -> Any:
    """A `--param` value as the wire carries it: angles typed in degrees (or
    with their unit) become radians; unknown spec: as typed (the server checks)."""
    if spec is None:
        return value
    wire, problem = value_from_text(spec, value)
    if problem is not None:
        raise UsageError(f"--param {name}: {problem}")
    return wire


def parse_params(items: list[str] | None) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for text in items or []:
        name, value = parse_param(text)
        if name in out:
            raise UsageError(f"--param {name} is given twice")
        out[name] = value
    return out


def _numbers(text: str, what: str, lo: int, hi: int) -> list[float]:
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    if not lo <= len(parts) <= hi:
        n = f"{lo}" if lo == hi else f"{lo} to {hi}"
        raise UsageError(f"{what}: expected {n} comma-separated numbers, got {text!r}")
    out = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise UsageError(f"{what}: {p!r} is not a number (in {text!r})") from None
        if not math.isfinite(v):
            raise UsageError(f"{what}: {p!r} is not a finite number")
        out.append(v)
    return out


def _mapping(text: str, what: str, fields: tuple[str, ...]) -> dict[str, float]:
    from backend.core.limits import echo
    from backend.files import yamlio

    try:
        data = yamlio.load(text).data
    except yamlio.YamlSyntaxError as e:
        raise UsageError(
            f"{what}: {echo(text)} is not a valid YAML mapping ({e.message})"
        ) from None
    if not isinstance(data, dict):
        raise UsageError(f"{what}: expected a mapping like {{x: 1, y: 2}}, got {text!r}")
    out = {}
    for k, v in data.items():
        if k not in fields:
            raise UsageError(f"{what}: unknown field {k!r} (fields: {', '.join(fields)})")
        if k in ANGLE_FIELDS:
            out[k] = _angle(v, f"{what}: {k}")
            continue
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise UsageError(f"{what}: {k} must be a finite number, got {v!r}")
        out[k] = float(v)
    return out


def _angle(v: Any, what: str) -> float:
    """An angle typed on the command line -> radians (bare numbers are degrees)."""
    rad, problem = parse_angle(v)
    if rad is None:
        raise UsageError(f"{what}: {problem}")
    return rad


def parse_pose(text: str) -> dict[str, float]:
    """`x,y[,z[,roll,pitch,yaw]]` or `{x: 1, y: 2, yaw: 90}`; angles in degrees
    unless they say `rad` (`yaw: 1.57rad`, `1,2,0,0,0,1.57rad`)."""
    if text.strip().startswith("{"):
        return _mapping(text, "--pose", POSE_FIELDS)
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    if not 2 <= len(parts) <= 6:
        raise UsageError(f"--pose: expected 2 to 6 comma-separated numbers, got {text!r}")
    coords = ",".join(parts[:3])
    out = dict(zip(POSE_FIELDS, _numbers(coords, "--pose", 2, 3), strict=False))
    for k, v in zip(ANGLE_FIELDS, parts[3:], strict=False):
        out[k] = _angle(v, f"--pose: {k}")
    return out


def parse_position(text: str, what: str = "--position") -> dict[str, float]:
    if text.strip().startswith("{"):
        return _mapping(text, what, POSITION_FIELDS)
    return dict(zip(POSITION_FIELDS, _numbers(text, what, 2, 3), strict=False))


def parse_area(text: str) -> list[dict[str, float]]:
    from backend.core.limits import echo
    from backend.files import yamlio

    stripped = text.strip()
    if stripped.startswith("["):
        try:
            data = yamlio.load(stripped).data
        except yamlio.YamlSyntaxError as e:
            raise UsageError(
                f"--area: {echo(text)} is not a valid YAML list ({e.message})"
            ) from None
        if not isinstance(data, list):
            raise UsageError(f"--area: expected a list of positions, got {text!r}")
        points = []
        for i, p in enumerate(data):
            if isinstance(p, dict):
                points.append(_mapping(json.dumps(p), f"--area point {i + 1}", POSITION_FIELDS))
            elif isinstance(p, list):
                points.append(parse_position(",".join(str(v) for v in p), f"--area point {i + 1}"))
            else:
                raise UsageError(
                    f"--area point {i + 1}: expected [x, y] or {{x: .., y: ..}}, got {p!r}"
                )
    else:
        chunks = [c for c in re.split(r"[;\s]+", stripped) if c]
        points = [parse_position(c, f"--area point {i + 1}") for i, c in enumerate(chunks)]
    if len(points) < 3:
        raise UsageError(
            f'--area: a polygon needs at least 3 points, got {len(points)} (write "x,y x,y x,y")'
        )
    return points
