"""Tests of the simulated fleet (sim/): world, map feed, skills, and the fleet against a real server."""
