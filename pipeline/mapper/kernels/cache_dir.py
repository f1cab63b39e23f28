"""Where numba keeps compiled kernels, decided before numba is imported.

numba writes its cache beside the source (``__pycache__``) and, when that directory is not
writable (a system-wide or read-only install), under the user's cache directory
(``~/.cache/numba``); when neither is writable it refuses to decorate a ``cache=True``
function at all. So: a ``NUMBA_CACHE_DIR`` set by the user is kept; otherwise, when neither
default location is writable, the cache goes to ``<temp>/sonarmap-numba-cache-<uid>``
(compiled once per machine boot instead of failing).
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

KERNELS_DIR = Path(__file__).resolve().parent


def _writable(path: Path) -> bool:
    """Whether ``path`` (or, if it does not exist yet, its nearest existing parent) is writable."""
    p = path
    while not p.exists():
        if p.parent == p:
            return False
        p = p.parent
    return os.access(p, os.W_OK | os.X_OK)


def _user_cache_dir() -> Path:
    """numba's per-user fallback (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "numba"


def choose_cache_dir(env: Mapping[str, str], kernels_dir: Path, user_dir: Path, temp_dir: Path,
                     writable: Callable[[Path], bool] = _writable) -> str | None:
    """The directory to put in ``NUMBA_CACHE_DIR``, or None to leave numba's defaults."""
    if env.get("NUMBA_CACHE_DIR"):
        return None
    if writable(kernels_dir / "__pycache__") or writable(user_dir):
        return None
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return str(temp_dir / f"sonarmap-numba-cache-{uid}")


def configure_cache_dir() -> None:
    """Set ``NUMBA_CACHE_DIR`` when numba's default cache locations are not writable."""
    chosen = choose_cache_dir(os.environ, KERNELS_DIR, _user_cache_dir(),
                              Path(tempfile.gettempdir()))
    if chosen is None:
        return
    os.environ["NUMBA_CACHE_DIR"] = chosen
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba imported already: its config read the environment then
        config.CACHE_DIR = chosen  # type: ignore[attr-defined]
