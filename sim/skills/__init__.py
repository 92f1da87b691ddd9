"""Skill handlers of the simulated robots (every skill of missions/libraries/mars.yaml).

`registry` names them (SKILLS) and puts one robot's on one object (RobotSkills);
`mobility`, `science`, `manipulation`, `aerial` and `power` hold the handlers by
family, over `base` (the steps they share) and `host` (what they need from the fleet).
"""
