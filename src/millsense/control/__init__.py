"""millsense.control."""
