"""How mission.db was made: by the code before skill events were typed
(main at 597c1e2), whose journal stores `skill_changed` and
`command_changed` events with a `changes` dict. Kept to say what the
fixture holds; run with that version on PYTHONPATH:

    PYTHONPATH=OLD_TREE python make.py mission.db mission_after.json
"""

import sys
from datetime import UTC, datetime
from pathlib import Path

from backend.core.ops import Answer, EditSkill, Report, Sync, UplinkSent
from backend.core.rules.engine import Engine
from backend.files.missions import load_mission
from backend.server.journal import Journal

out = Path(sys.argv[1])
T = datetime(2026, 3, 14, 10, 0, 0, tzinfo=UTC)
mission, library = load_mission("tests/data/mars_sample_return_v1.yaml")
e = Engine(mission, library)
with Journal.open(out, library="libraries/mars.yaml") as j:
    j.snapshot(e.mission)

    def rec(op, actor="console"):
        a = e.submit(op, client="c")
        j.append(a.batch(actor, op.op), op_json=op.model_dump_json())
        return a

    rec(EditSkill(id="lru1-2", label="a stone, carefully"))
    a = rec(Sync(robot="lru1", through="lru1-2"))
    c = e.mission.command(a.value["command"])
    rec(UplinkSent(robot="lru1", ids=[c.id], at=T), "server")
    rec(
        Answer(robot="lru1", seq=1, command=c.seq, outcome="applied", queued=c.skills, at=T), "lru1"
    )
    e.release("lru1")
    rec(Report(robot="lru1", seq=2, id="lru1-1", status="running", at=T), "lru1")
    rec(Report(robot="lru1", seq=3, id="lru1-1", status="success", info="arrived", at=T), "lru1")
    rec(Report(robot="lru1", seq=4, id="lru1-2", status="running", at=T), "lru1")
    rec(
        Report(robot="lru1", seq=5, id="lru1-2", status="failure", info="wheel stuck", at=T), "lru1"
    )
Path(sys.argv[2]).write_text(e.mission.model_dump_json())
