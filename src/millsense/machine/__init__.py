"""millsense.machine."""
