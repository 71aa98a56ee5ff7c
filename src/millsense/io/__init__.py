"""millsense.io."""
