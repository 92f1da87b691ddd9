"""`missionctl validate`: a corpus of malformed files, each with the exact
`file:line` and field path of every problem it must report.

The expectations live in `corpus/expected.yaml` (file name -> issues). The
contract is checked through the real command line (a subprocess, as users and
CI run it); properties that hold for every file are checked in-process for
speed.
"""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from backend.files.missions import validate_file

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
CORPUS = HERE / "corpus"
EXPECTED: dict[str, list[dict]] = yaml.safe_load(
    (CORPUS / "expected.yaml").read_text(encoding="utf-8")
)
CORPUS_FILES = sorted(p.name for p in CORPUS.iterdir() if p.is_file() and p.name != "expected.yaml")
SHIPPED = sorted(REPO.glob("missions/*.yaml")) + sorted(REPO.glob("missions/libraries/*.yaml"))

# `FILE:LINE:COL: rest` where rest is `PATH: message` or `message`
LINE_RE = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<col>\d+): (?P<rest>.*)$")

# Wording of pydantic or Python internals that must not reach an operator.
JARGON = (
    "Input should be",
    "after validation",
    "[key]",
    "Value error",
    "Keys should be",
    "input is too short",
    "Traceback",
)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )


@dataclass
class Reported:
    file: Path
    line: int
    col: int
    rest: str  # "PATH: message" or "message"
    raw: str


def parse_output(text: str) -> tuple[list[Reported], list[str]]:
    """(issue lines, other lines) of the command's output."""
    issues, other = [], []
    for raw in text.splitlines():
        m = LINE_RE.match(raw)
        if m:
            issues.append(
                Reported(Path(m["file"]).resolve(), int(m["line"]), int(m["col"]), m["rest"], raw)
            )
        elif raw.strip():
            other.append(raw)
    return issues, other


def _as_list(v) -> list[str]:
    if v is None:
        return []
    return [v] if isinstance(v, str) else list(v)


def matches(exp: dict, got: Reported, corpus_file: Path) -> bool:
    file = (CORPUS / exp["file"]).resolve() if "file" in exp else corpus_file.resolve()
    if got.file != file or got.line != exp["line"]:
        return False
    if "col" in exp and got.col != exp["col"]:
        return False
    path = exp.get("path", "")
    if path:
        if not got.rest.startswith(f"{path}: "):
            return False
        message = got.rest[len(path) + 2 :]
    else:
        message = got.rest
    if any(c not in message for c in _as_list(exp.get("contains"))):
        return False
    return not any(x in message for x in _as_list(exp.get("excludes")))


def describe(exp: dict) -> str:
    where = f"{exp.get('file', '<file>')}:{exp['line']}" + (
        f":{exp['col']}" if "col" in exp else ""
    )
    what = f"{exp.get('path', '')}: " if exp.get("path") else ""
    extra = ""
    if exp.get("contains") is not None:
        extra += f" containing {_as_list(exp['contains'])}"
    if exp.get("excludes") is not None:
        extra += f" without {_as_list(exp['excludes'])}"
    return f"{where}: {what}...{extra}"


def check_expectations(name: str, reported: list[Reported]) -> list[str]:
    """Problems with what was reported for corpus file `name`, as sentences."""
    corpus_file = CORPUS / name
    left = list(reported)
    problems = []
    for exp in EXPECTED[name]:
        hit = next((r for r in left if matches(exp, r, corpus_file)), None)
        if hit is None:
            problems.append(f"missing: {describe(exp)}")
        else:
            left.remove(hit)
    problems += [f"unexpected: {r.raw}" for r in left]
    return problems


# -- the corpus itself ---------------------------------------------------------------


def test_corpus_is_large_enough():
    assert len(CORPUS_FILES) >= 25
    missions = [f for f in CORPUS_FILES if not f.startswith("lib_")]
    libraries = [f for f in CORPUS_FILES if f.startswith("lib_")]
    assert len(missions) >= 15 and len(libraries) >= 5


def test_every_corpus_file_has_expectations():
    assert sorted(EXPECTED) == CORPUS_FILES
    for name, issues in EXPECTED.items():
        assert issues, f"{name}: a malformed file needs at least one expected issue"
        for exp in issues:
            assert isinstance(exp.get("line"), int) and "path" in exp, f"{name}: {exp}"


# -- the command line, file by file -------------------------------------------------


@pytest.mark.parametrize("name", CORPUS_FILES)
def test_corpus_file(name: str):
    r = run_cli("validate", str(CORPUS / name))
    out = r.stdout + r.stderr
    assert "Traceback" not in out, f"{name} crashed the validator:\n{out}"
    assert r.returncode == 2, f"{name}: exit {r.returncode}, expected 2\n{out}"
    reported, other = parse_output(out)
    assert not other, f"{name}: lines not in FILE:LINE:COL: form:\n" + "\n".join(other)
    problems = check_expectations(name, reported)
    assert not problems, f"{name}:\n  " + "\n  ".join(problems) + "\nactual output:\n" + out


def test_all_corpus_files_in_one_run():
    """One bad file never stops the others: each gets its own report."""
    files = [str(CORPUS / n) for n in CORPUS_FILES]
    r = run_cli("validate", *files)
    out = r.stdout + r.stderr
    assert r.returncode == 2
    assert "Traceback" not in out
    reported, _ = parse_output(out)
    named = {x.file for x in reported}
    missing = [n for n in CORPUS_FILES if (CORPUS / n).resolve() not in named]
    assert not missing, f"no issue reported for {missing}"


def test_shipped_files_are_valid():
    r = run_cli("validate", *[str(p) for p in SHIPPED])
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stderr == ""
    for p in SHIPPED:
        assert f"{p}: ok" in r.stdout.splitlines()


def test_quiet_prints_nothing_for_valid_files():
    r = run_cli("validate", "-q", *[str(p) for p in SHIPPED])
    assert r.returncode == 0
    assert r.stdout == "" and r.stderr == ""


def test_mix_of_valid_and_invalid_files():
    bad = [CORPUS / "out_of_bounds_max.yaml", CORPUS / "lib_undefined_skill.yaml"]
    r = run_cli("validate", str(SHIPPED[0]), str(bad[0]), str(SHIPPED[-1]), str(bad[1]))
    out = r.stdout + r.stderr
    assert r.returncode == 2, out
    assert "Traceback" not in out
    assert f"{SHIPPED[0]}: ok" in r.stdout.splitlines()
    assert f"{SHIPPED[-1]}: ok" in r.stdout.splitlines()
    assert (
        f"{bad[0]}:15:9: tasks.lru1[2].params.speed: 3.0 m/s is above the maximum 1 m/s" in r.stderr
    )
    assert f"{bad[1]}:6:24: robot_types.rover.skills[1]: unknown skill 'dig'" in r.stderr


def test_nonexistent_file():
    missing = CORPUS / "does_not_exist.yaml"
    r = run_cli("validate", str(missing), str(SHIPPED[0]))
    out = r.stdout + r.stderr
    assert r.returncode == 2
    assert "Traceback" not in out
    assert f"{missing}:1:1: no such file" in r.stderr
    assert f"{SHIPPED[0]}: ok" in r.stdout  # the other files are still checked


def test_directory_argument():
    r = run_cli("validate", str(CORPUS))
    assert r.returncode == 2
    assert "Traceback" not in r.stdout + r.stderr
    assert "is a directory" in r.stderr


def test_no_file_is_a_usage_error():
    r = run_cli("validate")
    assert r.returncode == 2
    assert "Traceback" not in r.stdout + r.stderr
    assert "usage:" in r.stderr


def test_relative_file_names_are_printed_as_given():
    rel = "tests/files/corpus/unknown_param.yaml"
    r = run_cli("validate", rel)
    assert r.returncode == 2
    assert r.stderr.startswith(f"{rel}:13:9: tasks.lru1[0].params.velocity: ")


# -- in-process: properties of every report (fast) ----------------------------------


@pytest.mark.parametrize("name", CORPUS_FILES)
def test_in_process_matches_expectations(name: str):
    """backend.files.missions.validate_file gives the same issues as the command line."""
    issues = validate_file(CORPUS / name)
    reported = []
    for i in issues:
        m = LINE_RE.match(str(i))
        assert m, f"not in FILE:LINE:COL: form: {i}"
        reported.append(Reported(Path(i.file).resolve(), i.line, i.col, m["rest"], str(i)))
    problems = check_expectations(name, reported)
    assert not problems, f"{name}:\n  " + "\n  ".join(problems)


@pytest.mark.parametrize("name", CORPUS_FILES)
def test_issues_are_in_line_order(name: str):
    issues = validate_file(CORPUS / name)
    by_file: dict[str, list[tuple[int, int]]] = {}
    for i in issues:
        by_file.setdefault(i.file, []).append((i.line, i.col))
    for file, marks in by_file.items():
        assert marks == sorted(marks), (
            f"{file}: issues not in line order: {[str(i) for i in issues]}"
        )


@pytest.mark.parametrize("name", CORPUS_FILES)
def test_messages_are_plain_sentences(name: str):
    """No pydantic wording ('Input should be', '[key]', ...) reaches the operator."""
    issues = validate_file(CORPUS / name)
    bad = [str(i) for i in issues if any(j in str(i) for j in JARGON)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_file_in_process(path: Path):
    assert validate_file(path) == []


def test_syntax_error_positions_are_one_based():
    issues = validate_file(CORPUS / "syntax_tab.yaml")
    assert [(i.line, i.col) for i in issues] == [(9, 1)]
