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
from datetime import UTC, date, datetime, timedelta
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


def parse_since(text: str, now: datetime | None = None) -> datetime:
    """`--since`: a duration ago ('30m', '2h'), a time today ('14:32',
    '14:32:05', local) or an ISO date-time. argparse's `type`."""
    import argparse

    now = now or datetime.now(UTC)
    ago = duration_s(text)
    if ago is not None:
        return now - timedelta(seconds=ago)
    try:
        if ":" in text and "-" not in text and "T" not in text:
            return _today_at(text, now)
        t = datetime.fromisoformat(text)
        return t if t.tzinfo else t.astimezone()
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"not a time: {text!r} (examples: 30m (ago), 14:32 (today), 2030-07-01T14:32)"
        ) from None


def _today_at(text: str, now: datetime) -> datetime:
    """'14:32' or '14:32:05', local, on `now`'s day (ValueError if it is none)."""
    parts = [int(x) for x in text.split(":")]
    h, m, s = (*parts, 0) if len(parts) == 2 else parts
    return now.astimezone().replace(hour=h, minute=m, second=s, microsecond=0)


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
    name, raw = _param_name(text)
    stripped = raw.strip()
    if stripped.startswith("@"):
        return name, AtMarker(check_name(stripped[1:], f"--param {name}=@MARKER"))
    value = _yaml_value(name, raw)
    if isinstance(value, dict | list) and stripped[:1] not in "{[":
        from backend.core.limits import echo

        raise UsageError(
            f"--param {name}: {echo(raw)} reads as a YAML block "
            f"{'mapping' if isinstance(value, dict) else 'list'}; write mappings in braces "
            "({x: 3, y: 4}) and lists in brackets ([a, b]), quoted for the shell"
        )
    if isinstance(value, str) and value.startswith("@") and len(value) > 1:
        return name, AtMarker(check_name(value[1:], f"--param {name}=@MARKER"))
    return name, _plain(value, f"--param {name}")


def _param_name(text: str) -> tuple[str, str]:
    """`NAME=VALUE` -> (NAME, VALUE as typed), NAME a parameter's name."""
    name, sep, raw = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise UsageError(
            f"--param {text!r}: expected NAME=VALUE (e.g. --param speed=0.5 or --param goal=@POI-A)"
        )
    if not _NAME_RE.match(name):
        raise UsageError(f"--param {text!r}: {name!r} is not a parameter name")
    return name, raw


def _yaml_value(name: str, raw: str) -> Any:
    """`--param NAME=RAW`'s value read as YAML, within the file limits (an
    alias bomb is refused here); a syntax error says how to write it."""
    from backend.core.limits import echo, show_path
    from backend.files import yamlio

    try:
        return yamlio.load(raw).data
    except yamlio.YamlSyntaxError as e:
        if not e.message.startswith("YAML"):  # over a limit
            where = show_path(e.path)
            raise UsageError(
                f"--param {name}: {f'{where}: ' if where else ''}{e.message}"
            ) from None
        why = e.message.removeprefix("YAML syntax error: ").splitlines()[0]
        raise UsageError(
            f"--param {name}: {echo(raw)} is not a valid YAML value ({why}){_yaml_hint(name, raw)}"
        ) from None


def _yaml_hint(name: str, raw: str) -> str:
    """How to write what the shell or YAML misread."""
    stripped = raw.strip()
    if stripped[:1] in "{[":
        return f"; quote the whole argument for the shell: --param '{name}={{x: 3, y: 4}}'"
    if ":" in stripped:
        return f"; write a mapping in braces: --param '{name}={{x: 3, y: 4}}'"
    return ""


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
        out[k] = _coordinate(v, what, k)
    return out


def _coordinate(v: Any, what: str, k: str) -> float:
    """Field `k` of a pose or position: an angle (in radians), or a finite number."""
    if k in ANGLE_FIELDS:
        return _angle(v, f"{what}: {k}")
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise UsageError(f"{what}: {k} must be a finite number, got {v!r}")
    return float(v)


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
    stripped = text.strip()
    if stripped.startswith("["):
        points = [_area_point(i, p) for i, p in enumerate(_area_list(text))]
    else:
        chunks = [c for c in re.split(r"[;\s]+", stripped) if c]
        points = [parse_position(c, f"--area point {i + 1}") for i, c in enumerate(chunks)]
    if len(points) < 3:
        raise UsageError(
            f'--area: a polygon needs at least 3 points, got {len(points)} (write "x,y x,y x,y")'
        )
    return points


def _area_list(text: str) -> list[Any]:
    """`--area '[[0, 0], {x: 1, y: 0}, ...]'`: the YAML list."""
    from backend.core.limits import echo
    from backend.files import yamlio

    try:
        data = yamlio.load(text.strip()).data
    except yamlio.YamlSyntaxError as e:
        raise UsageError(f"--area: {echo(text)} is not a valid YAML list ({e.message})") from None
    if not isinstance(data, list):
        raise UsageError(f"--area: expected a list of positions, got {text!r}")
    return data


def _area_point(i: int, p: Any) -> dict[str, float]:
    """Item `i` of an --area list: `[x, y]` or `{x: .., y: ..}`."""
    if isinstance(p, dict):
        return _mapping(json.dumps(p), f"--area point {i + 1}", POSITION_FIELDS)
    if isinstance(p, list):
        return parse_position(",".join(str(v) for v in p), f"--area point {i + 1}")
    raise UsageError(f"--area point {i + 1}: expected [x, y] or {{x: .., y: ..}}, got {p!r}")
