"""`missionctl schema`: JSON Schema of the mission and library formats,
generated from the models, that editors can validate YAML with."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
CORPUS = HERE / "corpus"
MISSIONS = sorted(REPO.glob("missions/*.yaml"))
LIBRARIES = sorted(REPO.glob("missions/libraries/*.yaml"))


def run_schema(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", "schema", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.fixture(scope="module")
def schemas() -> dict:
    r = run_schema()
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    return json.loads(r.stdout)


def validator(schema: dict):
    import jsonschema  # a dev dependency

    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def load_yaml(path: Path):
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def test_schema_prints_both_formats(schemas: dict):
    assert set(schemas) == {"mission", "library", "contact-windows"}
    for kind, s in schemas.items():
        assert s["type"] == "object", kind
        assert s["$schema"].startswith("https://json-schema.org/")
        assert s.get("title"), kind
        assert s["additionalProperties"] is False, (
            f"{kind}: unknown top-level fields must be refused"
        )
    assert schemas["mission"]["properties"]["format"]["const"] == "missionctl/mission@1"
    assert schemas["library"]["properties"]["format"]["const"] == "missionctl/library@1"
    assert "library" in schemas["mission"]["required"]
    assert schemas["contact-windows"]["properties"]["format"]["const"] == (
        "missionctl/contact-windows@1"
    )


@pytest.mark.parametrize("kind", ["mission", "library", "contact-windows"])
def test_schema_of_one_format(kind: str, schemas: dict):
    r = run_schema(kind)
    assert r.returncode == 0
    assert json.loads(r.stdout) == schemas[kind]


def test_schema_unknown_kind_is_a_usage_error():
    r = run_schema("robot")
    assert r.returncode == 2
    assert "Traceback" not in r.stderr


def test_schemas_are_valid_json_schema(schemas: dict):
    for s in schemas.values():
        validator(s)


def test_schema_is_generated_from_the_models(schemas: dict):
    from backend.files.schema import schemas as generate

    assert json.loads(json.dumps(generate())) == schemas


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: p.name)
def test_shipped_mission_matches_schema(path: Path, schemas: dict):
    errors = sorted(validator(schemas["mission"]).iter_errors(load_yaml(path)), key=str)
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors)


@pytest.mark.parametrize("path", LIBRARIES, ids=lambda p: p.name)
def test_shipped_library_matches_schema(path: Path, schemas: dict):
    errors = sorted(validator(schemas["library"]).iter_errors(load_yaml(path)), key=str)
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors)


def test_saved_mission_matches_schema(schemas: dict, tmp_path: Path):
    from backend.files.missions import library_path, load_mission, save_mission

    src = MISSIONS[0]
    m, _ = load_mission(src)
    out = tmp_path / "saved.yaml"
    save_mission(m, out, library_file=library_path(src, m.library))
    assert not list(validator(schemas["mission"]).iter_errors(load_yaml(out)))


@pytest.mark.parametrize(
    ("name", "kind", "where"),
    [
        ("unknown_top_field.yaml", "mission", []),
        ("bad_marker_kind.yaml", "mission", ["markers", "SPOT"]),
        ("invalid_status.yaml", "mission", ["tasks", "lru1", 0, "status"]),
        ("area_two_points.yaml", "mission", ["markers", "ROI-1"]),  # oneOf: reported at the marker
        ("barrier_single_skill.yaml", "mission", ["barriers", "b1", "skills"]),
        ("invalid_robot_name.yaml", "mission", ["robots"]),
        ("wrong_format_version.yaml", "mission", ["format"]),
        ("lib_unknown_field.yaml", "library", ["robot_types", "rover"]),
        ("lib_bad_param_type.yaml", "library", ["skills", "scan", "params", "resolution", "type"]),
    ],
)
def test_malformed_file_fails_schema(name: str, kind: str, where: list, schemas: dict):
    errors = list(validator(schemas[kind]).iter_errors(load_yaml(CORPUS / name)))
    assert errors, f"{name} passes the {kind} schema"
    paths = [list(e.absolute_path) for e in errors]
    assert any(p[: len(where)] == where for p in paths), paths
