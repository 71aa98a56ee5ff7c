"""millsense.report."""
