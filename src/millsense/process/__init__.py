"""millsense.process."""
