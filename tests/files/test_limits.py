"""Files held to the limits of backend/core/limits.py.

The corpus (corpus/limit_*.yaml, checked by test_validate.py like every
malformed file) has one small file per limit; the cases here are too large to
keep in the repository (over 100,000 entries, over 16 MiB), so they are
written at test time. Whether an alias bomb is refused with bounded memory is
checked in a subprocess under an address-space limit (its speed is a
benchmark: bench/bench_limits.py).
"""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import pytest

from backend.core.limits import LIMITS
from backend.files.missions import load_mission, save_mission, validate_file

from .test_validate import CORPUS, LINE_RE, REPO, parse_output

LIBRARY = REPO / "missions" / "libraries" / "mars.yaml"
HEAD = f"""format: missionctl/mission@1
name: limits
library: {LIBRARY}
robots:
  lru1: {{type: lru_science}}
"""
# a refusal echoes a short prefix of the value: no issue line is longer than this
MAX_LINE = 400


def _too_many_list_items() -> str:
    items = ", ".join(["20"] * (LIMITS.items + 1))
    return HEAD + (
        "tasks:\n  lru1:\n    - id: lru1-1\n      skill: take_science_image\n"
        f"      params:\n        target: {{x: 1, y: 2}}\n        camera: {{exposures: [{items}]}}\n"
    )


def _too_many_entries() -> str:
    markers = "".join(
        f"  m{i}: {{kind: position, position: {{x: 1}}}}\n" for i in range(LIMITS.items + 1)
    )
    return HEAD + "markers:\n" + markers


# name -> (file text, line, col, field path, words of the message)
GENERATED = {
    "list_items": (
        _too_many_list_items,
        12,
        18,
        "tasks.lru1[0].params.camera.exposures",
        "more than the limit of 100,000 items",
    ),
    "mapping_entries": (
        _too_many_entries,
        6,
        1,
        "markers",
        "more than the limit of 100,000 entries",
    ),
}


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("limits")
    out = {}
    for name, (text, *_) in GENERATED.items():
        out[name] = folder / f"{name}.yaml"
        out[name].write_text(text(), encoding="utf-8")
    return out


@pytest.mark.parametrize("name", sorted(GENERATED))
def test_generated_case_is_refused_where_it_breaks_the_limit(name, generated):
    _, line, col, path, words = GENERATED[name]
    [issue] = validate_file(generated[name])
    assert (issue.line, issue.col) == (line, col), str(issue)
    assert str(issue).startswith(f"{generated[name]}:{line}:{col}: {path}: "), str(issue)
    assert words in issue.message and len(str(issue)) < MAX_LINE


def test_generated_cases_through_the_command_line(generated):
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "validate", *map(str, generated.values())],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    reported, other = parse_output(r.stderr)
    assert not other and len(reported) == len(GENERATED), r.stderr
    for name, (_, line, col, path, words) in GENERATED.items():
        [hit] = [x for x in reported if x.file == generated[name].resolve()]
        assert (hit.line, hit.col) == (line, col) and hit.rest.startswith(f"{path}: ")
        assert words in hit.rest and len(hit.raw) < MAX_LINE


def test_a_file_over_the_size_limit_is_not_read(tmp_path):
    big = tmp_path / "big.yaml"
    with big.open("wb") as f:  # sparse: no 16 MiB written
        f.truncate(LIMITS.file + 1)
    [issue] = validate_file(big)
    assert (issue.line, issue.col, issue.path) == (1, 1, ())
    assert f"{LIMITS.file + 1:,} bytes, more than the limit of {LIMITS.file:,} bytes" in str(issue)


def test_every_corpus_message_is_short():
    """Whatever the file holds, an issue is one short line (the issue's 2 MB
    enum value was echoed whole)."""
    for f in sorted(CORPUS.glob("*.yaml")):
        for issue in validate_file(f):
            line = str(issue)
            assert len(line) < MAX_LINE and "\n" not in line, line
            assert LINE_RE.match(line), line


def _limit_memory() -> None:  # in the child, before it runs anything
    cap = 1 << 30  # 1 GiB of address space: the bomb took 7 GB
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    resource.setrlimit(resource.RLIMIT_CPU, (60, 60))  # a guard, not a measure


def test_an_alias_bomb_is_refused_within_bounded_memory():
    bomb = CORPUS / "limit_alias_bomb.yaml"
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "validate", str(bomb)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=_limit_memory,
    )
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "MemoryError" not in r.stderr
    assert f"{bomb}:10:14: g[2]: the file expands to more than the limit of" in r.stderr


def test_a_10000_skill_mission_file_is_within_the_limits(tmp_path):
    """The defaults fit real missions: bench/bench_core.py's 10,000 skills."""
    sys.path.insert(0, str(REPO / "bench"))
    try:
        from bench_core import big_mission
    finally:
        sys.path.remove(str(REPO / "bench"))
    m = big_mission()
    path = tmp_path / "big.yaml"
    save_mission(m, path, library_file=LIBRARY)
    loaded, _ = load_mission(path)
    assert sum(len(t) for t in loaded.tasks.values()) == 10_000
    assert path.stat().st_size < LIMITS.file / 4  # and far from the size limit
