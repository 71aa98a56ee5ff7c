"""``millsense info`` and ``millsense plot`` (filled in by the foundation work)."""
