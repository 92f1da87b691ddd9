"""The engine's recorder on the server: every batch goes into the journal
before it changes the mission (`Engine(recorder=...)`), so an operation the
journal cannot take changes nothing, in memory or at a restart."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from pydantic_core import PydanticSerializationError

from backend.core.alerts import AlertKind, Raises
from backend.core.events import EventBatch
from backend.core.rules.engine import Origin, Refusal
from backend.server.journal import Journal, JournalError, NotReplayable
from backend.server.refusals import JournalFailed


class JournalRecorder:
    """Writes each batch with its operation, client, request id and actor."""

    def __init__(self, journal: Journal, db: Path, alerts: Raises):
        self.journal = journal
        self.db = db
        self.alerts = alerts
        self.failing = False  # said once when it starts failing, once when it recovers

    def record(self, batch: EventBatch, origin: Origin) -> None:
        op = origin.op
        entry = EventBatch(revision=batch.revision, events=batch.events, actor=origin.actor)
        try:
            op_json = op.model_dump_json()
        except PydanticSerializationError:  # from code in this process: its batch says
            op_json = op.op
        try:
            self.journal.append(
                entry, op_json=op_json, client=origin.client, request_id=origin.request_id
            )
        except NotReplayable as e:  # the value, not the journal: refused, nothing changed
            raise Refusal(
                "not_replayable",
                f"{op.op} refused: its change could not be journaled as it is, so a "
                f"restart could not replay it: {e}; nothing was changed",
            ) from None
        except (sqlite3.Error, OSError, JournalError) as e:
            failed = JournalFailed(self.db, e, op.op)
            if not self.failing:  # once, not at every retry of every robot
                self.failing = True
                self.alerts.alert(failed.message, level="error", kind=AlertKind.JOURNAL)
            raise failed from None
        if self.failing:
            self.failing = False
            self.alerts.alert(
                f"the journal {self.db} can be written again", level="info", kind=AlertKind.JOURNAL
            )
