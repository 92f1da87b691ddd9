"""Tests of the simulated fleet (sim/): world, map feed, skills, the fleet against a server."""
