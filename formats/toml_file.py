"""Reading a TOML file (configuration, regression tolerances, simulated worlds) in one way.

Parsed with the standard library's ``tomllib``: no code is executed. Every failure is a
:class:`~formats.errors.ConfigError` of one line naming the file.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from formats.errors import ConfigError

__all__ = ["read_toml"]


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The parsed document; ``what`` names the file's role in messages ("configuration")."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        raise ConfigError(f"{what} file not found", p) from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"cannot read {what}: {err}", p) from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"invalid TOML: {err}", p) from err
