"""millsense.plan."""
