"""millsense.online."""
