"""Starting values for a new skill's parameters, from what the console knows."""

from __future__ import annotations

from typing import Any

from backend.core.params import ParamSpec, StartContext, starting_values
from console.state.model import ConsoleModel


def default_params(
    spec_params: dict[str, ParamSpec], model: ConsoleModel, robot: str
) -> tuple[dict[str, Any], dict[str, str]]:
    """Values for the required parameters without a default, so a new skill is
    valid at once (then edited): see `backend.core.params.starting_values`."""
    tel = model.telemetry.get(robot)
    ctx = StartContext(
        robot=robot,
        markers=model.mission.markers if model.mission else {},
        robots=tuple(model.mission.robots) if model.mission else (),
        **({"pose": tel.pose.model_dump()} if tel is not None else {}),
    )
    return starting_values(spec_params, ctx)
