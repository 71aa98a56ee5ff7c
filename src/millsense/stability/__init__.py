"""millsense.stability."""
