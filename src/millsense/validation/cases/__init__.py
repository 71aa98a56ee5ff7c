"""Validation case modules, one per package validated; every module here is loaded."""
