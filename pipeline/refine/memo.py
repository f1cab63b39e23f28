"""Pure evaluations remembered by their arguments: the calibration's searches ask for the
same scores and surface associations again."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class Memo(Generic[K, V]):
    """``compute()`` per ``key``, computed once: the value must be a pure function of the key
    (threads may ask for distinct keys at once; the first answer to a key is kept)."""

    def __init__(self) -> None:
        self._known: dict[K, V] = {}

    def get(self, key: K, compute: Callable[[], V]) -> V:
        if key not in self._known:
            self._known[key] = compute()
        return self._known[key]
