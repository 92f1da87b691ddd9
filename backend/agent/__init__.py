"""The robot-side SDK: connect a real or simulated robot to the mission server.

`from backend.agent import RobotAgent, Success, ...` is the integrator's API
(docs/robots.md); the modules of this package are its parts.
"""

from backend.agent.facade import (
    AlreadyConnected,
    Failure,
    Link,
    RegistrationRefused,
    RobotAgent,
    SkillContext,
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
