"""What the console knows and derives from it: no Textual here."""
