"""Outputs under an object-store prefix (``-o s3://bucket/prefix``): complete or marked so.

Object stores have no atomic rename, so "complete or absent" is a rule about the order of
writes. A run stages its files in a local temporary directory (:class:`OutputDir`'s
``path()``), then at commit:

1. ``.sonarmap-output.partial`` is written first: every object the commit may leave
   under the prefix (the old output's and the new one's);
2. an old output's marker is deleted (the prefix is incomplete from here), then its
   objects the new output does not have;
3. every new file is uploaded; 4. ``.sonarmap-output`` (the list of the files) is written
   LAST; 5. the partial list is deleted and the local staging removed.

A prefix is complete when it holds ``.sonarmap-output`` and exactly the objects it lists;
batch, regress and evaluate take nothing else as an output. A prefix may be replaced
(``--force``, a batch re-mapping a log) only when it is complete, or is an interrupted
commit (no marker; every object listed in the partial list); a prefix holding anything
else — objects sonarmap did not write — is refused, and nothing of it is deleted.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from formats.errors import InputError, OutputError, StorageError
from formats.storage.failures import is_not_found
from formats.storage.location import Location, Url
from formats.writers.atomic import OutputDir
from formats.writers.output_marker import (
    MAX_PROOF_BYTES,
    OUTPUT_MARKER,
    ReadRange,
    write_output_marker,
)

__all__ = ["PARTIAL_MARKER", "RemoteOutputDir", "RemoteState", "complete_output",
           "open_output_dir", "remote_state", "url_reader"]

PARTIAL_MARKER = ".sonarmap-output.partial"
_MARKERS = frozenset({OUTPUT_MARKER, PARTIAL_MARKER})
_MAX_LISTED = 3


@dataclass(frozen=True)
class RemoteState:
    """What is under a prefix: the objects (relative keys) and the two markers' lists."""

    present: frozenset[str]
    listed: frozenset[str] | None  # .sonarmap-output's files (None: absent or unreadable)
    partial: frozenset[str] | None  # .sonarmap-output.partial's files

    @property
    def files(self) -> frozenset[str]:
        return self.present - _MARKERS

    @property
    def complete(self) -> bool:
        """A finished sonarmap output: its marker lists exactly what is there."""
        return OUTPUT_MARKER in self.present and self.listed == self.files

    def not_replaceable_reason(self) -> str | None:
        """None when sonarmap may delete what is there (a complete output, an interrupted
        commit, nothing), else why not (one phrase)."""
        if not self.present or self.complete:
            return None
        if OUTPUT_MARKER not in self.present and self.partial is not None \
                and self.files <= self.partial:
            return None
        known = self.listed if OUTPUT_MARKER in self.present else self.partial
        if known is None and not (self.present & _MARKERS):
            return "is not a sonarmap output"
        unknown = sorted(self.files - (known or frozenset()))
        if unknown:
            shown = ", ".join(unknown[:_MAX_LISTED]) + (", ..." if len(unknown) > _MAX_LISTED
                                                        else "")
            return f"holds objects sonarmap did not write ({shown})"
        return "has an unreadable .sonarmap-output marker"


def _read_list(url: Url) -> frozenset[str] | None:
    try:
        data = json.loads(url.read_bytes())
    except (StorageError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return frozenset(files)


def remote_state(prefix: Url) -> RemoteState:
    """List ``prefix`` afresh (no cached listing) and read its markers."""
    fs = prefix.fs
    root = prefix.fs_path.rstrip("/")
    prefix.call("cannot list", lambda: fs.invalidate_cache())
    try:
        keys = prefix.call("cannot list", lambda: fs.find(root))
    except StorageError as err:
        if err.__cause__ is not None and is_not_found(err.__cause__):
            keys = []
        else:
            raise
    present = frozenset(k[len(root) + 1:] for k in keys if k.startswith(root + "/"))
    listed = _read_list(prefix / OUTPUT_MARKER) if OUTPUT_MARKER in present else None
    partial = _read_list(prefix / PARTIAL_MARKER) if PARTIAL_MARKER in present else None
    return RemoteState(present, listed, partial)


class RemoteOutputDir(OutputDir):
    """:class:`~formats.writers.atomic.OutputDir` for a URL prefix: the same ``path()`` and
    refusals, staged locally and uploaded in the order of the module docstring."""

    def __init__(self, final: Url, force: bool = False,
                 protect: tuple[Location, ...] = ()) -> None:
        self.url = final
        self.force = force
        self.remote_protect = tuple(protect)
        self.final = Path(final.name or "output")  # for OutputDir's messages only
        self.protect = ()
        self._tmp: Path | None = None
        self.committed = False

    def _check_remote(self) -> None:
        url = self.url
        if url.protocol in ("http", "https"):
            raise OutputError("outputs cannot be written to http(s) URLs; use an object "
                              "store (s3://, gs://, az://) or a local directory", url)
        if not url.name:
            raise OutputError("output prefix needs a name below the bucket", url)
        for p in self.remote_protect:
            if isinstance(p, Url) and p.is_inside(url):
                raise OutputError(f"contains the input {p}; not writing there, choose another "
                                  "output prefix", url)
        state = remote_state(url)
        reason = state.not_replaceable_reason()
        if reason is not None:
            raise OutputError(f"exists and {reason}; not replacing it, choose another output "
                              "prefix", url)
        if state.present and not self.force:
            what = ("an earlier sonarmap output" if state.complete else
                    "an incomplete sonarmap output: an upload was interrupted")
            raise OutputError(f"exists already ({what}); use --force to replace it, or choose "
                              "another output prefix", url)

    def __enter__(self) -> RemoteOutputDir:
        self._check_remote()
        self._tmp = Path(tempfile.mkdtemp(prefix="sonarmap-upload-"))
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        try:
            super().__exit__(exc_type, exc, tb)
        finally:
            if self._tmp is not None:
                shutil.rmtree(self._tmp, ignore_errors=True)

    def _public_error(self, exc: BaseException, tmp: Path) -> OutputError:
        if isinstance(exc, OutputError):
            return OutputError(exc.reason.replace(str(tmp), str(self.url)), self.url)
        return OutputError(f"cannot write: {exc}", self.url)

    def _commit(self, tmp: Path) -> None:
        try:
            write_output_marker(tmp)
            self._upload(tmp)
        except StorageError as err:
            raise OutputError(f"upload failed, the prefix is left without a "
                              f"{OUTPUT_MARKER} marker (incomplete): {err.reason}",
                              self.url) from err
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        self.committed = True

    def _upload(self, tmp: Path) -> None:
        url = self.url
        fs = url.fs
        new = sorted(p.relative_to(tmp).as_posix() for p in tmp.rglob("*")
                     if p.is_file() and p.name != OUTPUT_MARKER)
        state = remote_state(url)  # again: it may have changed while we mapped
        reason = state.not_replaceable_reason()
        if reason is not None:
            raise OutputError(f"exists and {reason}; not replacing it", url)
        if state.present and not self.force:
            raise OutputError("exists already; use --force to replace it", url)
        partial = json.dumps({"written_by": "sonarmap",
                              "files": sorted(set(new) | state.files)}, indent=1) + "\n"

        def put(rel: str, data: bytes | None = None) -> None:
            target = (url / rel).fs_path
            if data is None:
                url.call("cannot upload", lambda: fs.put_file(str(tmp / rel), target))
            else:
                url.call("cannot upload", lambda: fs.pipe_file(target, data))

        def delete(rel: str) -> None:
            url.call("cannot delete", lambda: fs.rm_file((url / rel).fs_path))

        put(PARTIAL_MARKER, partial.encode())
        if OUTPUT_MARKER in state.present:
            delete(OUTPUT_MARKER)
        for rel in sorted(state.files - set(new)):
            delete(rel)
        for rel in new:
            put(rel)
        put(OUTPUT_MARKER)
        delete(PARTIAL_MARKER)


def open_output_dir(final: Location, force: bool = False,
                    protect: tuple[Location, ...] = ()) -> OutputDir:
    """The output directory of a run: local (:class:`OutputDir`) or a URL prefix
    (:class:`RemoteOutputDir`)."""
    if isinstance(final, Url):
        return RemoteOutputDir(final, force=force, protect=protect)
    return OutputDir(final, force=force,
                     protect=tuple(p for p in protect if isinstance(p, Path)))


@contextlib.contextmanager
def complete_output(where: Location, what: str = "run") -> Iterator[Path]:
    """A run's output as a local directory: a local path as it is; a URL prefix copied to
    a temporary directory (removed after) only when it is complete — a prefix without its
    ``.sonarmap-output`` marker, or holding other objects, is an InputError (incomplete)."""
    if not isinstance(where, Url):
        yield where
        return
    state = remote_state(where)
    if not state.complete:
        why = ("not found" if not state.present else
               "incomplete: no .sonarmap-output marker (an upload was interrupted or is "
               "under way)" if OUTPUT_MARKER not in state.present else
               "incomplete: its .sonarmap-output marker does not list exactly what is there")
        raise InputError(f"{what} output {why}", where)
    tmp = Path(tempfile.mkdtemp(prefix="sonarmap-fetch-"))
    try:
        for rel in sorted(state.files):
            dst = tmp / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            (where / rel).download(dst)
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def url_reader(prefix: Url) -> ReadRange:
    """:data:`~formats.writers.output_marker.ReadRange` over the objects under ``prefix``
    (byte ranges, at most MAX_PROOF_BYTES; None when an object cannot be read), so that the
    ownership rule of :mod:`formats.writers.output_marker` judges objects as it judges
    files."""

    def read(name: str, offset: int, length: int) -> bytes | None:
        url = prefix / name
        length = max(0, min(length, MAX_PROOF_BYTES))
        try:
            size = url.stat().st_size
            start = max(0, size + offset) if offset < 0 else offset
            data: bytes = url.call("cannot read", lambda: url.fs.cat_file(
                url.fs_path, start=start, end=min(size, start + length)))
        except StorageError:
            return None
        return data

    return read
