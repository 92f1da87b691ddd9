"""The robot-side SDK: connect a real or simulated robot to the mission server.

`from backend.agent import RobotAgent, Success, ...` is the integrator's API
(docs/robots.md); the modules of this package are its parts:

- facade: RobotAgent, the API and the wiring of the parts below;
- queue: the synchronized queue as a state machine (no transport, no asyncio);
- execution: running the active skill's handler, its policies;
- context: SkillContext, what a handler gets; outcomes: how it ends;
- registration: manifest, presence, registering (one session per name, the
  server's reconciliation); uplink: the ground's commands, each applied once
  by sequence number; outbox: the downlink (reports and answers, one
  numbered sequence) until acknowledged;
- questions: a handler's questions to the operators (`ctx.ask_operator`);
- choices: markers whose place the robot chooses on board (`agent.on_choose`);
- telemetry, barriers, world (robot-to-robot ask/tell);
- link: the link model; runtime: the loop, session and link the parts share.
"""

from backend.agent.choices import Choice
from backend.agent.context import SkillContext
from backend.agent.facade import RobotAgent
from backend.agent.link import Link
from backend.agent.outcomes import (
    AlreadyConnected,
    Failure,
    RegistrationRefused,
    SkillFailed,
    SkillStopped,
    Success,
)
from backend.agent.questions import Reply
from backend.agent.telemetry import STEADY, TelemetryPolicy

__all__ = [
    "AlreadyConnected",
    "Choice",
    "Failure",
    "Link",
    "RegistrationRefused",
    "Reply",
    "RobotAgent",
    "STEADY",
    "SkillContext",
    "SkillFailed",
    "SkillStopped",
    "Success",
    "TelemetryPolicy",
]
