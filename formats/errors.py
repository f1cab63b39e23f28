"""The one exception hierarchy of sonarmap.

Every error that bad input, a bad configuration or a refused output can cause is a
:class:`SonarmapError`. Only ``cli/`` turns these into one-line messages and exit codes;
anything else that escapes is a bug and is shown with its traceback.

Messages name the file (when there is one) and say what was expected and what was found,
in one line: ``"<path>: <what is wrong>"``.
"""

from __future__ import annotations

from pathlib import Path


class SonarmapError(Exception):
    """Base of every error sonarmap raises on purpose."""

    def __init__(self, message: str, path: str | Path | object | None = None) -> None:
        # ``path``: a Path, a text, or a URL (whose str() is already redacted).
        self.path = None if path is None else str(path)
        self.reason = message
        text = message if path is None else f"{path}: {message}"
        # One line, always: error messages end up in CI logs and batch summaries.
        super().__init__(" ".join(text.split()))


class FormatError(SonarmapError):
    """A log file is unreadable, truncated, corrupt or of an unknown format."""


class TopicError(SonarmapError):
    """The requested topics are missing or ambiguous in a log."""


class ConfigError(SonarmapError):
    """A configuration file or option is invalid."""


class InputError(SonarmapError):
    """A log is readable but cannot be mapped (no ranges, no poses, no overlap, ...)."""


class OutputError(SonarmapError):
    """An output cannot be written (exists already, symlinked, outside the output dir)."""


class StorageError(SonarmapError):
    """A URL cannot be reached, read or written (not found, access denied, timed out,
    connection refused, the filesystem's extra not installed)."""
