"""Core data types: errors, units, recordings, configuration models."""
