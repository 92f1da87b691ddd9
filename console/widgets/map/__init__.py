"""The map region: the site drawn in half-blocks (view)."""
