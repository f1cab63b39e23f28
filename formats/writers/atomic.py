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

from formats.errors import InputError, OutputError
from formats.path_text import NAME_MAX
from formats.writers.output_marker import (
    not_replaceable_file_reason,
    not_replaceable_reason,
    write_output_marker,
)

__all__ = [
    "OutputDir",
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_output_file",
    "clean_stale_entries",
    "clean_stale_siblings",
    "fsync_path",
    "make_dir",
]

# What _sibling_name adds around the name: ".", ".tmp-", a pid (up to 10 digits), "-", 8 hex.
_SIBLING_EXTRA = len(".") + len(".tmp-") + 10 + len("-") + 8


def check_path_names(path: Path) -> None:
    """OutputError, before any work, when a component of ``path`` is longer than
    NAME_MAX bytes or cannot be encoded as a file name."""
    for part in Path(path).parts:
        try:
            size = len(os.fsencode(part))
        except UnicodeEncodeError as err:
            raise OutputError(f"a path component cannot be a file name ({err.reason})",
                              path) from err
        if size > NAME_MAX:
            raise OutputError(f"a path component is too long ({size} bytes; at most "
                              f"{NAME_MAX})", path)


def make_dir(path: Path, what: str) -> None:
    """Create directory ``path`` (and its parents) if missing; OutputError "cannot create
    the <what>: <reason>" naming it when the system refuses."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"cannot create the {what}: {err.strerror or err}", path) from err


def fsync_path(path: Path) -> None:
    """fsync a file or directory by path (directories: makes renames inside them durable)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) if path.is_dir() else os.O_RDONLY
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _names_other_file(err: OSError, tmp: Path) -> bool:
    """Whether ``err`` names a file outside the temporary directory ``tmp`` (one the work
    read: everything an output directory writes is inside ``tmp``)."""
    name = err.filename
    return isinstance(name, str) and not _inside(Path(os.path.abspath(name)),
                                                 Path(os.path.abspath(tmp)))


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


# ``run`` is the staging directory of batches before they used OutputDir (dead = garbage).
_STALE = re.compile(r"\.(?P<name>.+)\.(?P<tag>tmp|old|run)-(?P<pid>\d+)-[0-9a-f]{8}")


def clean_stale_siblings(final: Path) -> list[Path]:
    """Remove what runs killed before they finished (SIGKILL, power loss) left next to
    ``final``: ``.<name>.tmp-<pid>-<hex>`` directories of processes that no longer exist,
    and ``.<name>.old-<pid>-<hex>`` ones when ``final`` itself exists. Returns what was
    removed. Siblings of live processes (a concurrent run) are left alone.
    """
    return _clean_stale(final.parent, final.name)


def clean_stale_entries(parent: Path) -> list[Path]:
    """:func:`clean_stale_siblings` for every name in ``parent`` (a batch's output directory
    at start: the staging its interrupted predecessors left, whatever log it was for)."""
    return _clean_stale(parent, None)


def _clean_stale(parent: Path, name: str | None) -> list[Path]:
    removed: list[Path] = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for p in sorted(entries):
        m = _STALE.fullmatch(p.name)
        if m is None or (name is not None and m["name"] != name):
            continue
        if p.is_symlink() or not p.is_dir() or _pid_alive(int(m["pid"])):
            continue  # a concurrent run's (or batch worker's) directory stays
        # A dead run's old copy is only garbage once a newer complete run is in place.
        if m["tag"] == "old" and not (parent / m["name"]).is_dir():
            continue
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def _inside(p: Path, root: Path) -> bool:
    return p == root or p.is_relative_to(root)


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
    exception propagates, as an OutputError naming ``final`` when it is an OSError (a full
    disk). The commit lists every file in ``.sonarmap-output``
    (:mod:`formats.writers.output_marker`). With ``force`` an existing ``final`` is renamed
    aside, the new one renamed in, then the old one deleted — the final name never holds a
    partial run — but only when ``final`` is a sonarmap output holding nothing else.

    Refuses (OutputError): an existing ``final`` without ``force``; one that is not a
    sonarmap output, holds other files, is not a directory, is or contains the working
    directory or one of ``protect`` (the input log); a ``final`` or parent that is a
    symlink; a parent that is a file; a name too long for its temporary sibling. Entering
    also removes the stale temporary siblings of runs that were killed
    (:func:`clean_stale_siblings`).
    """

    def __init__(
        self, final: Path, force: bool = False, protect: tuple[Path, ...] = ()
    ) -> None:
        self.final = Path(final)
        self.force = force
        self.protect = tuple(Path(p) for p in protect)
        self._tmp: Path | None = None
        self.committed = False

    # -- checks -------------------------------------------------------------------------

    def _check_final(self) -> None:
        final = self.final
        if final.name in ("", ".", ".."):
            raise OutputError("output directory needs a name (not '.', '..' or '/')", final)
        check_path_names(final)
        if final.is_symlink():
            raise OutputError("output directory is a symlink; refusing to write through it", final)
        if final.parent.is_symlink():
            raise OutputError(
                "parent of the output directory is a symlink; refusing to write through it",
                final.parent,
            )
        if len(os.fsencode(final.name)) + _SIBLING_EXTRA > NAME_MAX:
            raise OutputError(
                f"output directory name is too long ({len(os.fsencode(final.name))} bytes; "
                f"at most {NAME_MAX - _SIBLING_EXTRA})",
                final,
            )
        for anc in final.parents:
            if anc.exists() or anc.is_symlink():
                if not anc.is_dir():
                    raise OutputError("is a file, not a directory: cannot create the output "
                                      "directory inside it", anc)
                break
        if final.exists():
            self._check_replaceable()

    def _check_replaceable(self) -> None:
        """An existing ``final`` may only be replaced when it is a previous sonarmap output
        (and ``force``); the refusal never suggests --force for anything else."""
        final = self.final
        if not final.is_dir():
            raise OutputError("exists and is not a directory; choose another output "
                              "directory", final)
        real = final.resolve()
        kept = [(p, f"the input {p}") for p in self.protect]
        with contextlib.suppress(OSError):  # a deleted working directory contains nothing
            kept.append((Path.cwd(), "the working directory"))
        for p, what in kept:
            rp = p.resolve()
            if rp == real or rp.is_relative_to(real):
                raise OutputError(f"is or contains {what}; not replacing it, choose another "
                                  "output directory", final)
        reason = not_replaceable_reason(final)
        if reason is not None:
            raise OutputError(f"exists and {reason}; not replacing it, choose another "
                              "output directory", final)
        if not self.force:
            raise OutputError("exists already (an earlier sonarmap output); use --force to "
                              "replace it, or choose another output directory", final)

    # -- context manager ----------------------------------------------------------------

    def __enter__(self) -> OutputDir:
        self._check_final()
        try:
            self.final.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:  # named by OUT, the user's name, and where it failed
            where = f" (at {err.filename})" if isinstance(err.filename, str) else ""
            raise OutputError(f"cannot create the output directory: "
                              f"{err.strerror or err}{where}", self.final) from err
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
                # Named by OUT, the user's name, not by the hidden temporary directory.
                raise OutputError(f"cannot create the output directory: "
                                  f"{err.strerror or err}", self.final) from err
            except BaseException:
                # SIGTERM/Ctrl-C right after mkdir: __exit__ will not run for a failed
                # __enter__, so the directory is removed here.
                _remove(tmp)
                raise
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
            if isinstance(exc, OSError) and _names_other_file(exc, tmp):
                # Not the output's: a file the work read (a name too long, EACCES ...).
                raise InputError(f"cannot open: {exc.strerror or exc}", exc.filename) from exc
            if isinstance(exc, OSError) or (
                isinstance(exc, OutputError) and exc.path and _inside(Path(exc.path), tmp)
            ):
                raise self._public_error(exc, tmp) from exc
            return  # the exception propagates
        try:
            self._commit(tmp)
        except BaseException:
            _remove(tmp)
            raise

    def _public_error(self, exc: BaseException, tmp: Path) -> OutputError:
        """``exc`` as an OutputError naming ``final`` (the user's name), not the hidden
        temporary directory it happened in."""
        if isinstance(exc, OutputError):
            where, reason = Path(exc.path or tmp), exc.reason
        else:
            err = exc if isinstance(exc, OSError) else OSError(str(exc))
            where = Path(err.filename) if isinstance(err.filename, str) else tmp
            reason = f"cannot write: {err.strerror or err}"
        target = self.final / where.relative_to(tmp) if _inside(where, tmp) else self.final
        return OutputError(reason.replace(str(tmp), str(self.final)), target)

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
            write_output_marker(tmp)
            for dirpath, _dirnames, filenames in os.walk(tmp):
                for fname in filenames:
                    p = Path(dirpath) / fname
                    if not p.is_symlink():
                        fsync_path(p)
                fsync_path(Path(dirpath))
        except OSError as err:
            raise OutputError(f"cannot sync output files: {err}", self.final) from err

        final = self.final
        # Checked again at commit time: os.rename would silently replace an empty directory.
        if final.is_symlink():
            raise OutputError("output directory is a symlink; refusing to replace it", final)
        old: Path | None = None
        if final.exists():
            self._check_replaceable()  # again: it may have appeared while we mapped
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
            fsync_path(final.parent)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or os.path.samefile(a, b)
    except (OSError, RuntimeError):
        return False


def check_output_file(
    path: Path,
    *,
    kind: str | None,
    force: bool,
    inputs: tuple[tuple[Path, str], ...] = (),
) -> None:
    """Refuse (OutputError, before any work) to write the single file ``path`` when it is,
    or is inside, one of ``inputs`` (``(path, what)``: "the truth map"), is a symlink or not a
    regular file, or exists and is not a sonarmap file of ``kind``
    (:func:`~formats.writers.output_marker.stamped`; None: no existing file is replaced);
    one that is sonarmap's is replaced only with ``force``. Messages suggest --force only
    for that last case."""
    path = Path(path)
    for p, what in inputs:
        p = Path(p)
        inside = p.is_dir() and _inside(Path(os.path.abspath(path)).resolve(), p.resolve())
        if inside or _same_file(path, p):
            how = "is inside" if inside else "is"
            raise OutputError(f"{how} {what}, an input of this command; choose another "
                              "output file", path)
    if not (path.exists() or path.is_symlink()):
        return
    reason = (not_replaceable_file_reason(path, kind) if kind is not None
              else "exists already")
    if reason is not None:
        raise OutputError(f"{reason}; not replacing it, choose another output file", path)
    if not force:
        raise OutputError("exists already (an earlier sonarmap output); use --force to "
                          "replace it, or choose another output file", path)


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
        if _names_other_file(err, tmp) and Path(os.path.abspath(err.filename)) != Path(
                os.path.abspath(path)):
            # Not the output's: a file the work read (a name too long, EACCES ...).
            raise InputError(f"cannot open: {err.strerror or err}", err.filename) from err
        if isinstance(err, FileNotFoundError) and not path.parent.is_dir():
            raise OutputError("parent directory does not exist", path) from err
        raise OutputError(f"cannot write: {err.strerror or err}", path) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    # Some filesystems refuse directory fsync; the data itself is synced.
    with contextlib.suppress(OSError):
        fsync_path(path.parent)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path) as f:
        f.write(data)


def atomic_write_text(path: Path, text: str) -> None:
    """Write UTF-8 ``text`` (``\\n`` newlines, on every OS) to ``path`` atomically. A file
    name's bytes that are not UTF-8 (surrogate-escaped) are written as ``\\udcXX``."""
    atomic_write_bytes(path, text.encode("utf-8", errors="backslashreplace"))
