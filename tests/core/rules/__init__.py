"""Unit tests of the pure operation rules (backend.rules.Engine)."""
