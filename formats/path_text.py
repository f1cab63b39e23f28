"""Paths spelled in the content of a file (a batch manifest line, a suite's ``path``, a map
YAML's ``image``, a bag's ``relative_file_paths``): checked before the OS sees them.

The OS refuses some byte sequences outright, with errors that mislead or escape as
tracebacks: a NUL byte (``ValueError: embedded null byte`` from ``open``/``realpath``), a
component longer than :data:`NAME_MAX` bytes or a path longer than :data:`PATH_MAX`
(``ENAMETOOLONG``, which ``exists()`` turns into a silent False: "no such file"), text
that cannot be encoded as a file name. :func:`path_text_problem` says which, in words;
:func:`shown` shortens such a text for a one-line message.
"""

from __future__ import annotations

import os

__all__ = ["NAME_MAX", "PATH_MAX", "path_text_problem", "shown"]

NAME_MAX = 255  # bytes in one path component (Linux, macOS, Windows)
PATH_MAX = 4096  # bytes in a whole path, its terminating NUL included (Linux)
_SHOWN = 60  # characters of a long path text a message shows


def path_text_problem(text: str) -> str | None:
    """Why the OS cannot take ``text`` as a path, or None when it can."""
    if not text:
        return "is empty"
    if "\x00" in text:
        return "contains a NUL byte, which no file name may hold"
    try:
        raw = os.fsencode(text)
    except UnicodeEncodeError as err:
        return f"cannot be a file name ({err.reason})"
    if len(raw) >= PATH_MAX:
        return f"is {len(raw)} bytes long; a path may have at most {PATH_MAX - 1}"
    longest = max(len(part) for part in raw.split(b"/"))
    if longest > NAME_MAX:
        return (f"has a name of {longest} bytes; a file or directory name may have at most"
                f" {NAME_MAX}")
    return None


def shown(text: str) -> str:
    """``text`` as a message quotes it: repr (control bytes visible), long ones cut in the
    middle with their length said."""
    if len(text) <= _SHOWN:
        return repr(text)
    half = _SHOWN // 2
    return f"{text[:half]!r}...{text[-half:]!r} ({len(text)} characters)"
