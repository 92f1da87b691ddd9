"""The rules engine: the one place that decides what may change in a mission."""
