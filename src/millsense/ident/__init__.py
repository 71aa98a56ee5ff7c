"""millsense.ident."""
