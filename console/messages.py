"""The console's messages: events in, and what the screens ask of the app.

In: `Incoming` carries one event for the model as it is: the client
library's (`backend.client.events`) or the console's own about itself
(console/state/changes.py). The live connection (`console.bridge`) posts
them; tests post the same ones, which is what makes snapshots deterministic
and lets every screen be tested without a network.

Up: a screen never imports the app; it posts one of the requests below and
the app handles it (messages up, state down). Operations are not messages:
screens submit them to the `OperationService` they were handed and await
their outcome in their own worker.
"""

from __future__ import annotations

from textual.message import Message

from console.state.changes import ModelEvent


class Incoming(Message):
    """One event for the model (a state, a batch, a robot, telemetry, an alert...)."""

    def __init__(self, event: ModelEvent) -> None:
        super().__init__()
        self.event = event


class HelpRequested(Message):
    """F1 / ?: show the key map (with the user's remappings)."""


class AlertAcknowledged(Message):
    """The operator acknowledged an alert (`alert_id` None: all of them)."""

    def __init__(self, alert_id: int | None) -> None:
        super().__init__()
        self.alert_id = alert_id


class QuestionRequested(Message):
    """Open a robot's question to answer it (`question_id` None: the oldest open one)."""

    def __init__(self, question_id: int | None) -> None:
        super().__init__()
        self.question_id = question_id
