"""The test suite; its folders mirror the layers (core, files, server, agent, cli, console, sim)."""
