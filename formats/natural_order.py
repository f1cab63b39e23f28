"""Natural order of names: ``sonar_2`` before ``sonar_10`` (digit runs compare as numbers)."""

from __future__ import annotations

import re

__all__ = ["natural_key"]

_DIGITS = re.compile(r"(\d+)")


def natural_key(name: str) -> tuple[tuple[tuple[int, int | str], ...], str]:
    """Sort key: text parts compare case-insensitively, digit runs by value; names equal
    that way (``a01`` and ``a1``, ``S1`` and ``s1``) then by their text, so the order is fixed."""
    parts: list[tuple[int, int | str]] = []
    for i, part in enumerate(_DIGITS.split(name)):
        if i % 2:
            parts.append((0, int(part)))
        elif part:
            parts.append((1, part.casefold()))
    return tuple(parts), name
