"""Exchange two directory entries in one step, where the system can.

Linux (glibc 2.28+, most local file systems) has ``renameat2(..., RENAME_EXCHANGE)``: both
names always exist and each holds one of the two trees, whenever the process dies.
:func:`exchange` returns False where that call is missing or refused (another OS, a file
system without it); the caller then falls back to two renames and must be able to recover
the moment between them.
"""

from __future__ import annotations

import ctypes
import errno
import os
import sys
from pathlib import Path

__all__ = ["exchange"]

_AT_FDCWD = -100
_RENAME_EXCHANGE = 2
_UNSUPPORTED = frozenset({errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP})


def _renameat2() -> object | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_FN = _renameat2()


def exchange(a: Path, b: Path) -> bool:
    """Swap what the names ``a`` and ``b`` (both existing, same file system) hold, in one
    step. False when the system cannot (nothing was changed); OSError on other failures."""
    if _FN is None:
        return False
    result = _FN(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b),  # type: ignore[operator]
                 _RENAME_EXCHANGE)
    if result == 0:
        return True
    err = ctypes.get_errno()
    if err in _UNSUPPORTED:
        return False
    raise OSError(err, os.strerror(err), str(a), None, str(b))
