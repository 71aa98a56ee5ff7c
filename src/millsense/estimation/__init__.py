"""millsense.estimation."""
