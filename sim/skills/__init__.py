"""Skill handlers of the simulated robots (every skill of missions/libraries/mars.yaml)."""
