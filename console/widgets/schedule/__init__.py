"""The schedule region: the robots' columns (view) and how each row is drawn (lines)."""
