"""docs/protocol.md is generated from the protocol models: keep it current."""

from pathlib import Path

from backend.protocol.doc import render


def test_protocol_doc_is_up_to_date():
    doc = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"
    assert doc.read_text(encoding="utf-8") == render(), (
        "docs/protocol.md is stale: run `python -m backend.protocol.doc > docs/protocol.md`"
    )


def test_protocol_doc_names_every_key_and_sequence():
    text = render()
    for needle in (
        "mc/v1/server/op",
        "mc/v1/robot/ROBOT/cmd",
        "### Unsynchronize",
        "### Barriers",
        '"Request"',
    ):
        assert needle in text
