"""The brief's import boundaries, checked on the source (no import needed):
backend never imports console, sim or textual; sim never imports console or
textual; console reaches the server only through backend (never sim)."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "backend": {"console", "sim", "textual"},
    "sim": {"console", "textual"},
    "console": {"sim"},
}


def imported_modules(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
    return out


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_respects_boundaries(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"package {package} has no Python files"
    bad = []
    for f in files:
        for line, mod in imported_modules(f):
            if mod.split(".")[0] in FORBIDDEN[package]:
                bad.append(f"{f.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "import boundary broken:\n" + "\n".join(bad)


def test_checker_sees_violations(tmp_path):
    # the checker itself must be able to fail
    f = tmp_path / "x.py"
    f.write_text("import textual.app\nfrom console import ui\n")
    assert [m for _, m in imported_modules(f)] == ["textual.app", "console"]


def test_import_linter_contracts_hold():
    """Same rules through import-linter's graph (catches indirect imports)."""
    import subprocess
    import sys

    lint = Path(sys.executable).with_name("lint-imports")
    r = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
