"""millsense.monitoring."""
