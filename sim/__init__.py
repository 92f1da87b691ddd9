"""The simulated fleet: a Mars sample-return site and its robots, on backend's robot agent SDK.

- `worldfile`: world files (`missions/worlds/*.yaml`), validated by pydantic;
- `world`: the site (numpy grids: terrain, explored area, coverage), objects, rules;
- `pathing`: A* on the terrain grid, sweeps;
- `skills/`: the robots' skill handlers (every skill of missions/libraries/mars.yaml), by
  family, over the `SkillHost` protocol the fleet satisfies; `skills.registry` names them;
- `exchange`: what a robot answers when another one asks or tells it about the world;
- `calibration`: the figures an operator plans with, from the world file and the skills
  (the robots' manifests declare them; a skill library that says otherwise is warned of);
- `fleet`: one RobotAgent per mission robot on one asyncio loop, map feed (wire models in
  backend.protocol.mapfeed), status;
- `cli`: `missionctl sim` and `missionctl sim-status`.

Never imports console or textual.
"""
