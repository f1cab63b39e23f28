"""Reading a TOML file (configuration, regression tolerances, simulated worlds) in one way.

Parsed with the standard library's ``tomllib``: no code is executed. Every failure is a
:class:`~formats.errors.ConfigError` of one line naming the file.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from formats.errors import ConfigError
from formats.text_file import read_text

__all__ = ["read_toml"]


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The parsed document; ``what`` names the file's role in messages ("configuration")."""
    text = read_text(path, f"{what} file", errors=(ConfigError, ConfigError))
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"invalid TOML: {err}", path) from err
