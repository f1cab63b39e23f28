"""Reading a whole text file with the one-line errors every reader gives."""

from __future__ import annotations

from pathlib import Path

from formats.errors import FormatError, InputError, SonarmapError

__all__ = ["read_text"]


def read_text(
    path: str | Path,
    what: str,
    *,
    errors: tuple[type[SonarmapError], type[SonarmapError]] = (InputError, FormatError),
    encoding: str = "utf-8",
) -> str:
    """The file's text. ``what`` names its role in messages ("trajectory file"): the first
    of ``errors`` says "<path>: <what> not found", the second "<path>: cannot read <what>:
    <reason>" (unreadable, a directory, not ``encoding``)."""
    missing, unreadable = errors
    try:
        return Path(path).read_text(encoding=encoding)
    except FileNotFoundError as err:
        raise missing(f"{what} not found", path) from err
    except (OSError, UnicodeDecodeError) as err:
        raise unreadable(f"cannot read {what}: {err}", path) from err
