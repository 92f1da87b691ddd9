"""The robot-side SDK: connect a real or simulated robot to the mission server.

`from backend.agent import RobotAgent, Success, ...` is the integrator's API
(docs/robots.md); the modules of this package are its parts.
"""

from backend.agent.facade import RobotAgent, SkillContext
from backend.agent.link import Link
from backend.agent.outcomes import (
    AlreadyConnected,
    Failure,
    RegistrationRefused,
    SkillFailed,
    SkillStopped,
    Success,
)

__all__ = [
    "AlreadyConnected",
    "Failure",
    "Link",
    "RegistrationRefused",
    "RobotAgent",
    "SkillContext",
    "SkillFailed",
    "SkillStopped",
    "Success",
]
