"""Unit tests of the pure operation rules (backend.core.rules.engine.Engine)."""
