"""millsense.virtual."""
