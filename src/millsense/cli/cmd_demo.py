"""``millsense demo`` (filled in by the foundation work)."""
