"""Errors that are the user's to fix.

Every error a user can cause (a malformed program, configuration or recording) is raised as a
:class:`UserError` subclass whose message is one line naming the file, key, line or channel.
The CLI prints that line and exits with status 2; it never shows a traceback for these.
"""

from __future__ import annotations


class UserError(Exception):
    """An error caused by input the user can correct. ``str(err)`` is the one-line message."""

    exit_code = 2

    def __init__(self, message: str) -> None:
        # Keep the message on one line whatever the caller passes.
        super().__init__(" ".join(str(message).split()))


class ConfigError(UserError):
    """Invalid configuration file or value."""


class RecordingError(UserError):
    """A recording that cannot be read, or a request it cannot answer (unknown channel...)."""


class ProgramError(UserError):
    """A part program (G-code) that cannot be interpreted."""


class InputDataError(UserError):
    """Data that is present but unusable (NaN in a channel, wrong length...)."""
