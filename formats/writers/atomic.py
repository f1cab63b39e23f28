"""Outputs are complete or absent: an atomically committed output directory and single files.

A run writes everything into a hidden temporary sibling of its output directory and renames
it into place only when every file is written and synced, so a crash, a full disk or an
exception never leaves a half-written result under the final name.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path, PurePath
from types import TracebackType
from typing import BinaryIO

from formats.errors import OutputError

__all__ = ["OutputDir", "atomic_open", "atomic_write_bytes", "atomic_write_text", "clean_stale_siblings"]


def _fsync_path(path: Path) -> None:
    """fsync a file or directory by path (directories: makes renames inside them durable)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) if path.is_dir() else os.O_RDONLY
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sibling_name(final: Path, tag: str) -> Path:
    return final.parent / f".{final.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def _pid_alive(pid: int) -> bool:
    """Whether a process with this id exists (on this host)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    except OSError:
        return True  # cannot tell: keep its files
    return True


_STALE = re.compile(r"\.(?P<name>.+)\.(?P<tag>tmp|old)-(?P<pid>\d+)-[0-9a-f]{8}")


def clean_stale_siblings(final: Path) -> list[Path]:
    """Remove what runs killed before they finished (SIGKILL, power loss) left next to
    ``final``: ``.<name>.tmp-<pid>-<hex>`` directories of processes that no longer exist,
    and ``.<name>.old-<pid>-<hex>`` ones when ``final`` itself exists. Returns what was
    removed. Siblings of live processes (a concurrent run) are left alone.
    """
    removed: list[Path] = []
    parent = final.parent
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for p in sorted(entries):
        m = _STALE.fullmatch(p.name)
        if m is None or m["name"] != final.name or p.is_symlink() or not p.is_dir():
            continue
        if _pid_alive(int(m["pid"])):
            continue
        # A dead run's old copy is only garbage once a newer complete run is in place.
        if m["tag"] == "old" and not final.is_dir():
            continue
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def _remove(path: Path) -> None:
    """Remove a file or directory tree if it exists (best effort: used on cleanup paths)."""
    if path.is_symlink() or path.is_file():
        path.unlink(missing_ok=True)
    elif path.is_dir():
        shutil.rmtree(path, ignore_errors=True)


class OutputDir:
    """A directory that appears under ``final`` complete, or not at all.

    ``with OutputDir(final, force) as out:`` creates ``.<name>.tmp-<pid>-<random>`` next to
    ``final``; ``out.path("map.pgm")`` names files inside it. On a clean exit every file is
    fsynced and the directory renamed to ``final``; on an exception it is removed and the
    exception propagates. With ``force`` an existing ``final`` directory is renamed aside,
    the new one renamed in, then the old one deleted — the final name never holds a partial
    run. Refuses (OutputError) an existing ``final`` without ``force``, a ``final`` that is
    not a directory, and a ``final`` or parent that is a symlink. Entering also removes the
    stale temporary siblings of runs that were killed (:func:`clean_stale_siblings`).
    """

    def __init__(self, final: Path, force: bool = False) -> None:
        self.final = Path(final)
        self.force = force
        self._tmp: Path | None = None
        self.committed = False

    # -- checks -------------------------------------------------------------------------

    def _check_final(self) -> None:
        final = self.final
        if final.name in ("", ".", ".."):
            raise OutputError("output directory needs a name (not '.', '..' or '/')", final)
        if final.is_symlink():
            raise OutputError("output directory is a symlink; refusing to write through it", final)
        if final.parent.is_symlink():
            raise OutputError(
                "parent of the output directory is a symlink; refusing to write through it",
                final.parent,
            )
        if final.exists():
            if not self.force:
                raise OutputError("exists already; use --force to replace", final)
            if not final.is_dir():
                raise OutputError("exists and is not a directory; not replacing it", final)

    # -- context manager ----------------------------------------------------------------

    def __enter__(self) -> OutputDir:
        self._check_final()
        try:
            self.final.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"cannot create parent directory: {err}", self.final.parent) from err
        # The symlink check again: mkdir may have just created the parent.
        self._check_final()
        clean_stale_siblings(self.final)
        for _ in range(16):
            tmp = _sibling_name(self.final, "tmp")
            try:
                # os.mkdir, not tempfile.mkdtemp: mkdtemp's 0o700 would become the mode of
                # the final directory; this one follows the umask like any other directory.
                os.mkdir(tmp)
            except FileExistsError:
                continue
            except OSError as err:
                raise OutputError(f"cannot create temporary directory: {err}", tmp) from err
            self._tmp = tmp
            return self
        raise OutputError("cannot find a free temporary directory name", self.final.parent)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        tmp = self._tmp
        self._tmp = None
        if tmp is None:
            return
        if exc_type is not None:
            _remove(tmp)
            return  # the exception propagates
        try:
            self._commit(tmp)
        except BaseException:
            _remove(tmp)
            raise

    @property
    def tmp_dir(self) -> Path:
        """The temporary directory being filled (only inside the ``with`` block)."""
        if self._tmp is None:
            raise OutputError("output directory is not open (use it inside 'with')", self.final)
        return self._tmp

    def path(self, name: str | PurePath) -> Path:
        """The path of ``name`` inside the output directory; creates its subdirectories.

        Refuses absolute names and names with ``..`` or otherwise leading outside.
        """
        tmp = self.tmp_dir
        rel = PurePath(name)
        text = str(name)
        if not text or rel.is_absolute() or rel.anchor or ".." in rel.parts or rel == PurePath():
            raise OutputError(f"output name {text!r} leads outside the output directory", tmp)
        target = tmp / rel
        # Belt and braces: resolve, so a symlink created inside cannot lead outside either.
        root = tmp.resolve()
        if not target.resolve().is_relative_to(root) or target.resolve() == root:
            raise OutputError(f"output name {text!r} leads outside the output directory", tmp)
        if target.parent != tmp:
            target.parent.mkdir(parents=True, exist_ok=True)
        return target

    # -- commit -------------------------------------------------------------------------

    def _commit(self, tmp: Path) -> None:
        try:
            for dirpath, _dirnames, filenames in os.walk(tmp):
                for fname in filenames:
                    p = Path(dirpath) / fname
                    if not p.is_symlink():
                        _fsync_path(p)
                _fsync_path(Path(dirpath))
        except OSError as err:
            raise OutputError(f"cannot sync output files: {err}", self.final) from err

        final = self.final
        # Checked again at commit time: os.rename would silently replace an empty directory.
        if final.is_symlink():
            raise OutputError("output directory is a symlink; refusing to replace it", final)
        old: Path | None = None
        if final.exists():
            if not self.force:
                raise OutputError("exists already; use --force to replace", final)
            old = _sibling_name(final, "old")
            try:
                os.rename(final, old)
            except OSError as err:
                raise OutputError(f"cannot move the old output aside: {err}", final) from err
        try:
            os.rename(tmp, final)
        except OSError as err:
            if old is not None:
                os.rename(old, final)  # put the previous complete run back
            raise OutputError(
                f"cannot rename the finished output into place: {err}", final
            ) from err
        self.committed = True
        # Some filesystems refuse directory fsync; the rename itself is done.
        with contextlib.suppress(OSError):
            _fsync_path(final.parent)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def atomic_open(path: Path) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through, atomically: a temporary sibling that is
    fsynced and renamed over ``path`` when the block ends without an error, and removed
    otherwise (so large outputs can be streamed, not held in memory)."""
    path = Path(path)
    tmp = _sibling_name(path, "tmp")
    try:
        with open(tmp, "xb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write: {err.strerror or err}", path) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    # Some filesystems refuse directory fsync; the data itself is synced.
    with contextlib.suppress(OSError):
        _fsync_path(path.parent)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path) as f:
        f.write(data)


def atomic_write_text(path: Path, text: str) -> None:
    """Write UTF-8 ``text`` (``\\n`` newlines, on every OS) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))
