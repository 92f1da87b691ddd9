"""The timeline region: per-robot lanes of the plan's forecast (view)."""
