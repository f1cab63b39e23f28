"""``run_batch()``: many logs mapped in parallel on Dask, one task per log.

Each log is mapped exactly as ``sonarmap run`` would (:func:`pipeline.run.run`) into
``OUT/<name>/``. A log is a file or bag directory, or — named on one manifest line with
`` + `` between the paths — one recording in several files (split bags, separate sonar and
odometry bags), read as one log like ``sonarmap run a.bag b.bag``. The engine is
``dask.distributed``: a local cluster of single-threaded worker processes (default), or an
existing cluster reached by its scheduler address.
Only paths, the configuration (a plain dict) and small result dicts travel through the
scheduler; each worker opens and streams its own input.

Resume: a finished log's directory holds ``.sonarmap-done.json`` (input sha256, config
hash and its summary values). The marker is written into the run's own staging directory
(:class:`~formats.writers.atomic.OutputDir`) before it is committed, so a directory under
the final name with a marker is always complete; one without a marker (a plain
``sonarmap run`` output) is re-mapped and replaced. Only sonarmap outputs are replaced:
an ``OUT/<name>`` that is an input, holds one or holds the user's files makes that log
fail with a one-line reason. A log whose input sha256 and config hash match its marker is
skipped unless ``rerun``. At start, the staging directories of interrupted batches whose
processes are dead are removed (a concurrent batch's are left alone).

Failure isolation: a log that raises :class:`~formats.errors.SonarmapError` is recorded
with its one-line message; any other exception with its type, message and traceback (the
traceback is logged); the other logs complete. The summary (``summary.parquet``,
``summary.md``, one row per log sorted by path) is written atomically at the end.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import logging
import os
import re
import secrets
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from formats.errors import (
    ConfigError,
    FormatError,
    InputError,
    OutputError,
    SonarmapError,
)
from formats.path_text import path_text_problem, shown
from formats.storage.location import Location, Url, as_location
from formats.storage.urls import is_url
from formats.tables import markdown_table
from formats.text_file import MAX_LIST_BYTES, read_bounded, read_text
from formats.writers.output_marker import SUMMARY_MD_TITLE
from pipeline.config import Config, config_from_dict, load_config
from pipeline.cores import usable_cores
from pipeline.stages.metrics_schema import finite, read_metrics

if TYPE_CHECKING:
    from pipeline.stages.metrics import RunMetrics

log = logging.getLogger("sonarmap.batch")

MARKER = ".sonarmap-done.json"
SUMMARY_PARQUET = "summary.parquet"
SUMMARY_MD = "summary.md"
MARKER_VERSION = 1
MAX_MARKER_BYTES = 1 << 20  # a resume marker is a few hundred bytes
MAX_NAME_BYTES = 200  # an output name, so that OutputDir's temporary sibling fits 255
SCHEDULER_TIMEOUT_S = 10.0
# Memory per local worker process: Dask's "auto" is the machine's memory / the workers.
MEMORY_LIMIT = "auto"  # connecting to an existing scheduler (--scheduler)
# The least --memory-limit a local worker can map with: a warmed worker holds ~270 MB
# before its first log (imports, kernels; measured RSS), and Dask pauses a worker at 80 %
# of its limit — below this a worker would never start a log, and the batch would wait
# forever. Refused up front.
MIN_MEMORY_LIMIT = 512 << 20
# Local workers must have joined the cluster within this (s), else the batch fails.
WORKERS_TIMEOUT_S = 120.0
# How often a batch looks at its workers (s), and how long none may be able to run a task
# (all paused by their memory limit, or none alive) before the logs left fail (s).
WATCH_S = 2.0
POLL_S = 0.1  # how often finished tasks are collected (s)
STALL_S = 20.0
# Local workers warm up (imports, compiled kernels) as the cluster starts, not in their
# first log (:mod:`pipeline.tools.batch_warm`).
WORKER_PRELOAD = "pipeline.tools.batch_warm"

BatchProgress = Callable[[int, int], None]  # (logs finished, logs total)
# A log: a file or bag directory, or the files of one recording (a manifest line
# ``a.bag + b.bag``, as sonarmap names such a recording: run_input.log_label).
LogInput = Location | tuple[Location, ...]
# What separates the files of one recording on a manifest line: a '+' with a blank (or the
# line's end) on each side.
_SEPARATOR = re.compile(r"(?:^|\s)\+(?:\s|$)")

# A file detected as CSV is only taken as a log when directory search finds it if it
# is not one of these (looks_like_csv accepts any text with two fields per line).
_NOT_LOG_SUFFIXES = frozenset(
    {".md", ".rst", ".toml", ".yaml", ".yml", ".json", ".html", ".htm", ".py", ".cfg",
     ".ini", ".xml", ".pgm", ".sh", ".in"}
)
_LOG_SUFFIXES = frozenset({".bag", ".mcap", ".db3"})
_HEADERLESS_SUFFIXES = frozenset({".csv", ".tsv", ".txt", ".dat", ".log"})
_SINGLE_COLUMNS = frozenset({"t", "x", "y", "yaw", "sensor", "range"})
_RESERVED_NAMES = frozenset({SUMMARY_PARQUET, SUMMARY_MD})


# --------------------------------------------------------------------------- results


@dataclass
class LogOutcome:
    """One summary row: a log and what happened to it.

    ``duration_s`` is the log's own duration (s); ``seconds`` the wall time spent on it in
    this batch (s). Mapping values are None when the log failed.
    """

    path: str
    name: str
    status: str  # "ok", "failed" or "skipped"
    error: str | None = None
    duration_s: float | None = None
    readings: int | None = None
    features: int | None = None
    mean_feature_variance_m2: float | None = None
    mapped_area_m2: float | None = None
    seconds: float = 0.0
    warnings: str | None = None  # the run's warnings (data lost, readings dropped), "; "

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LogOutcome:
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


@dataclass
class BatchResult:
    """What a batch did: one outcome per log (sorted by path) and where the summary is."""

    out_dir: Location
    outcomes: list[LogOutcome]
    summary_parquet: Location
    summary_md: Location

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    @property
    def failures(self) -> list[LogOutcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    @property
    def unread(self) -> list[LogOutcome]:
        """Directories the search could not read (skipped rows with a reason)."""
        return [o for o in self.outcomes if o.status == "skipped" and o.error is not None]

    @property
    def ok(self) -> bool:
        """True when no log failed (skipped logs are finished ones)."""
        return not self.failures


# --------------------------------------------------------------------------- finding logs


def read_manifest(path: Path) -> list[LogInput]:
    """The logs a manifest lists: one per line, ``#`` comments and blank lines ignored,
    relative paths taken relative to the manifest's directory; a line with `` + ``
    between paths names one recording in several files (a tuple of its paths)."""
    # utf-8-sig: a byte-order mark is not a path
    text = read_text(path, "manifest", errors=(InputError, InputError), encoding="utf-8-sig",
                     max_bytes=MAX_LIST_BYTES)
    out: list[LogInput] = []
    for number, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue  # only whole-line comments: a path may contain '#'
        parts = [part.strip() for part in _SEPARATOR.split(s)]
        if not all(parts):
            raise InputError(f"line {number}: an empty path beside '+' in {shown(s)}", path)
        for part in parts:
            problem = None if is_url(part) else path_text_problem(part)
            if problem is not None:
                raise InputError(f"line {number}: the path {shown(part)} {problem}", path)
        files = tuple(_manifest_path(path, part) for part in parts)
        out.append(files[0] if len(files) == 1 else files)
    return out


def _manifest_path(manifest: Path, text: str) -> Location:
    if is_url(text):
        return as_location(text)
    p = Path(text).expanduser()
    return p if p.is_absolute() else Path(manifest).parent / p


def log_files(log_input: LogInput) -> tuple[Location, ...]:
    """The file(s) of a log."""
    return log_input if isinstance(log_input, tuple) else (log_input,)


def log_text(log_input: LogInput) -> str:
    """A log as summary rows and messages name it (:func:`pipeline.streaming.run_input.log_label`)."""
    from pipeline.streaming.run_input import log_label

    return str(log_label(log_files(log_input)))


def _is_log_dir(d: Path, config: Config) -> bool:
    """A directory that is one log: a rosbag2 bag or a CSV log set."""
    from formats.csv_log import looks_like_csv

    return (d / "metadata.yaml").is_file() or looks_like_csv(d, config)


def _is_log_file(f: Path, config: Config) -> bool:
    """Whether directory search takes ``f`` as a log: its content must be a known format,
    and a CSV must be a single-layout log (right header, or a data-file suffix)."""
    from formats import detect_format

    if ".truth." in f.name or f.suffix.lower() in _NOT_LOG_SUFFIXES:
        return False
    try:
        fmt = detect_format(f)
    except FormatError:
        # A file named like a log (an empty or cut .bag) is a log that fails, not noise.
        return f.suffix.lower() in _LOG_SUFFIXES
    if fmt != "csv":
        return True
    csv = config.input.csv
    if csv.layout != "single":
        return False  # set layouts are directories, found as such
    if not csv.header:
        return f.suffix.lower() in _HEADERLESS_SUFFIXES
    return _single_header_ok(f, csv.delimiter)


def _single_header_ok(f: Path, delimiter: str) -> bool:
    try:
        with f.open("r", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                s = line.strip()
                if not s or s.startswith("#"):
                    continue
                parts = s.split() if delimiter == "whitespace" else s.split(delimiter)
                names = {p.strip().strip('"').lower() for p in parts}
                return names >= _SINGLE_COLUMNS
    except OSError:
        return False
    return False


@dataclass(frozen=True)
class Unread:
    """A directory the search could not read (listed as a skipped row, with its reason)."""

    path: Path
    reason: str


def _search(
    d: Path, config: Config, skip: set[Path], seen: set[tuple[int, int]], unread: list[Unread]
) -> Iterator[Path]:
    """Logs under directory ``d``, recursively, in sorted order. Each real directory is
    walked once (``seen``: device and inode), so symlink loops end; a directory that cannot
    be listed goes to ``unread``. In a directory sonarmap wrote (its marker, or its
    metrics.json: :mod:`formats.writers.output_marker`), the files it wrote are not logs;
    any other file there is searched like anywhere else."""
    from formats.writers.output_marker import local_reader, written_files

    try:
        st = d.stat()
        if (st.st_dev, st.st_ino) in seen:
            return
        seen.add((st.st_dev, st.st_ino))
        entries = sorted(d.iterdir(), key=lambda p: p.name)
    except OSError as err:
        unread.append(Unread(d, f"cannot list directory: {err.strerror or err}"))
        return
    ours = written_files([e.name for e in entries], local_reader(d)) or frozenset()
    for e in entries:
        if e.name.startswith(".") or e.name in ours or _resolved(e) in skip:
            continue  # hidden: staging and temporary dirs, VCS metadata
        if e.is_dir():
            if _is_log_dir(e, config):
                yield e
            else:
                yield from _search(e, config, skip, seen, unread)
        elif e.is_file() and _is_log_file(e, config):
            yield e


def _resolved(p: Path) -> Path:
    try:
        return p.resolve()
    except (OSError, RuntimeError):  # a symlink loop
        return Path(os.path.abspath(p))


def find_logs(
    inputs: Sequence[Location],
    config: Config,
    *,
    manifests: Sequence[Path] = (),
    exclude: Sequence[Location] = (),
    unread: list[Unread] | None = None,
) -> list[LogInput]:
    """The logs a batch maps, deduplicated and sorted by absolute path.

    Files named directly or in a manifest are taken as they are (a failure to read them
    is that log's failure); so is a manifest's recording in several files. Directories are
    one log when they are a rosbag2 bag (a ``metadata.yaml``) or a CSV log set, else
    searched recursively for files whose content is a log; hidden entries, ``*.truth.*``
    files, the files sonarmap wrote and ``exclude`` are skipped. Directories that cannot be
    listed are appended to ``unread``.
    """
    skip = {_resolved(Path(p)) for p in exclude if isinstance(p, Path)}
    named: list[LogInput] = [as_location(p) for p in inputs]
    for m in manifests:
        named += read_manifest(Path(m))
    found: dict[Location | tuple[Location, ...], LogInput] = {}
    seen: set[tuple[int, int]] = set()
    unread = [] if unread is None else unread
    for p in named:
        if isinstance(p, tuple):
            # In path order: a recording is read in time order whatever order names it,
            # so its name and row do not depend on it either.
            files = tuple(sorted((_absolute(f) for f in p), key=str))
            found.setdefault(tuple(sorted((_key(f) for f in files), key=str)), files)
            continue
        if isinstance(p, Url):  # taken as it is: a URL is not searched
            found.setdefault(p, p)
            continue
        ap = Path(os.path.abspath(p))
        if os.path.isdir(ap) and not _is_log_dir(ap, config):  # False on any OSError
            for f in _search(ap, config, skip, seen, unread):
                found.setdefault(_resolved(f), Path(os.path.abspath(f)))
        else:
            found.setdefault(_resolved(ap), ap)
    return sorted(found.values(), key=log_text)


def _absolute(f: Location) -> Location:
    return f if isinstance(f, Url) else Path(os.path.abspath(f))


def _key(f: Location) -> Location:
    """What tells two logs apart: a path resolved, a URL as it is."""
    return f if isinstance(f, Url) else _resolved(f)


def _base_name(f: Location) -> str:
    """A log's output name: a file's stem, a directory's name (a URL's without asking the
    server: its stem when it has a suffix and no trailing '/')."""
    if isinstance(f, Url):
        return f.stem if f.suffix and not f.text.endswith("/") else f.name
    return f.name if os.path.isdir(f) else f.stem


def output_names(paths: Sequence[LogInput]) -> dict[LogInput, str]:
    """Output directory name of each log: the file stem (or directory name), the stems
    joined by ``+`` for a recording in several files; names that collide
    (case-insensitively, or with the summary files) all get ``-<8 hex of the sha256 of the
    path>``, so a name depends only on its own path and its peers; a name longer than
    MAX_NAME_BYTES is cut and gets the same suffix (its output directory and the temporary
    sibling must fit the file system's 255-byte limit)."""
    base = {p: "+".join(_base_name(f) or "log" for f in log_files(p)) for p in paths}
    counts: dict[str, int] = {}
    for n in base.values():
        counts[n.casefold()] = counts.get(n.casefold(), 0) + 1
    out = {}
    for p, n in base.items():
        long = len(os.fsencode(n)) > MAX_NAME_BYTES
        if counts[n.casefold()] > 1 or n in _RESERVED_NAMES or n.startswith(".") or long:
            digest = hashlib.sha256(log_text(p).encode()).hexdigest()[:8]
            n = f"{_clip(n, MAX_NAME_BYTES - 9)}-{digest}"
        out[p] = n
    return out


def _clip(name: str, max_bytes: int) -> str:
    """``name`` cut to at most ``max_bytes`` of UTF-8 (on a character boundary)."""
    raw = os.fsencode(name)[:max_bytes]
    return raw.decode("utf-8", errors="ignore") or "log"


# --------------------------------------------------------------------------- the worker


def _map_one(
    path: str | list[str], out_dir: str, name: str, config: dict[str, Any], rerun: bool
) -> dict[str, Any]:
    """Map one log (a path, or the files of one recording) into ``out_dir/name`` (runs on
    a Dask worker); never raises.

    Returns a :class:`LogOutcome` as a dict, plus ``traceback`` (text) for unexpected
    exceptions.
    """
    t0 = time.perf_counter()
    files = tuple(as_location(p) for p in ([path] if isinstance(path, str) else path))
    label = log_text(files)
    try:
        row = _map_one_checked(files, as_location(out_dir), name, config, rerun)
    except SonarmapError as err:
        row = LogOutcome(label, name, "failed", error=str(err))
    except Exception as err:  # a bug or an unforeseen library error: record, go on
        msg = " ".join(f"{type(err).__name__}: {err}".split())
        return {**asdict(LogOutcome(label, name, "failed", error=msg,
                                    seconds=time.perf_counter() - t0)),
                "traceback": traceback.format_exc()}
    row.seconds = time.perf_counter() - t0
    return asdict(row)


def _map_one_checked(
    files: tuple[Location, ...], out_dir: Location, name: str, config: dict[str, Any],
    rerun: bool
) -> LogOutcome:
    from formats.storage.options import configure
    from pipeline.run import run
    from pipeline.streaming.run_input import files_sha256, hashes_sha256

    cfg = config_from_dict(config)
    configure(cfg.storage)  # this worker reaches URLs with the batch's options
    for f in files:
        if isinstance(f, Url):  # a URL asks its server
            if not f.exists():
                raise InputError("no such file or directory", f)
            continue
        try:
            os.lstat(f)
        except FileNotFoundError:
            raise InputError("no such file or directory", f) from None
        except (OSError, ValueError) as err:  # a name too long, a NUL byte, EACCES ...
            reason = err.strerror if isinstance(err, OSError) and err.strerror else err
            raise InputError(f"cannot open: {reason}", f) from None
    path = log_text(files)
    final = out_dir / name
    config_hash = cfg.hash()
    marker = None if rerun else read_marker(final)
    if (
        marker is not None
        and marker.get("config_hash") == config_hash
        and marker.get("input_sha256") == files_sha256(files)  # hashed only when it can matter
    ):
        saved = marker.get("row")
        saved = saved if isinstance(saved, dict) else {}
        return LogOutcome.from_dict(
            {**saved, "path": path, "name": name, "status": "skipped", "error": None}
        )
    from formats.writers.atomic import atomic_write_text

    outcome: list[LogOutcome] = []

    def add_marker(tmp_dir: Path, _: RunMetrics) -> None:
        # The row holds what the run wrote: its metrics.json, read through the schema.
        m = read_metrics(tmp_dir / "metrics.json")
        inp, counts = m.get("input", {}), m.get("counts", {})
        row = LogOutcome(
            path=path,
            name=name,
            status="ok",
            duration_s=finite(inp.get("duration_s")),
            readings=counts["readings"],
            features=counts["features"],
            mean_feature_variance_m2=finite(
                m.get("paper_metric", {}).get("mean_feature_variance_m2")
            ),
            mapped_area_m2=finite(m.get("map", {}).get("mapped_area_m2")),
            warnings="; ".join(m.get("warnings", [])) or None,
        )
        marker_data = {
            "marker_version": MARKER_VERSION,
            # files_sha256 of the input, from the hashes the run made (no file read again)
            "input_sha256": inp["sha256"] if len(files) == 1 else hashes_sha256(
                [f["sha256"] for f in inp["files"]]),
            "config_hash": config_hash,
            "tool_version": m.get("run", {}).get("tool_version"),
            "row": {k: v for k, v in asdict(row).items()
                    if k not in ("path", "status", "error", "seconds")},
        }
        atomic_write_text(tmp_dir / MARKER, json.dumps(marker_data, indent=2) + "\n")
        outcome.append(row)

    # The run's own OutputDir stages, commits and replaces: only a previous sonarmap
    # output of this log is ever replaced, never an input or the user's files.
    run(files[0] if len(files) == 1 else list(files), final, cfg, force=True,
        on_complete=add_marker)
    return outcome[0]


def read_marker(run_dir: Location) -> dict[str, Any] | None:
    """The resume marker of a finished log's output directory, or None (absent/unreadable;
    under a URL prefix also when the prefix is incomplete: an interrupted upload is never
    taken as done)."""
    if isinstance(run_dir, Url):
        from formats.writers.remote_output import remote_state

        if not remote_state(run_dir).complete:
            return None
    try:
        data = json.loads(read_bounded(run_dir / MARKER, "resume marker", MAX_MARKER_BYTES))
    except (SonarmapError, ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


# --------------------------------------------------------------------------- the driver


@contextlib.contextmanager
def _client(
    workers: int | None, scheduler: str | None, memory_limit: str | int = MEMORY_LIMIT
) -> Iterator[Any]:
    """A Dask client: to ``scheduler`` if given, else to a new local process cluster."""
    with _quiet_dask():
        yield from _client_inner(workers, scheduler, memory_limit)


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask logs cluster life (INFO) to the root handler; keep only its errors unless
    sonarmap itself logs at DEBUG (``-vv``)."""
    import distributed  # noqa: F401  (its import configures its loggers: before the level is set)

    dlog = logging.getLogger("distributed")
    old = dlog.level
    if logging.getLogger("sonarmap").getEffectiveLevel() > logging.DEBUG:
        dlog.setLevel(logging.ERROR)
    try:
        yield
    finally:
        dlog.setLevel(old)


def parse_memory_limit(memory_limit: str | int) -> str | int:
    """``--memory-limit`` as Dask takes it: "auto", or bytes (0: no limit); ConfigError
    for a size no worker can start a log under (:data:`MIN_MEMORY_LIMIT`)."""
    if memory_limit == "auto":
        return memory_limit
    from dask.utils import format_bytes, parse_bytes

    try:
        value = parse_bytes(memory_limit)
    except (ValueError, TypeError) as err:
        raise ConfigError(
            f"--memory-limit must be 'auto' or a size like 4GB, got {memory_limit!r}"
        ) from err
    if 0 < value < MIN_MEMORY_LIMIT:  # 0: no limit (Dask)
        raise ConfigError(
            f"--memory-limit {format_bytes(value)} is below what a worker holds before its "
            f"first log; give at least {format_bytes(MIN_MEMORY_LIMIT)} (or auto)"
        )
    return value


def _client_inner(
    workers: int | None, scheduler: str | None, memory_limit: str | int = MEMORY_LIMIT
) -> Iterator[Any]:
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise ConfigError(
                f"cannot connect to the Dask scheduler at {scheduler}: {err}"
            ) from err
        with client:
            yield client
        return
    n = workers if workers is not None else usable_cores()
    if n < 1:
        raise ConfigError(f"--workers must be >= 1, got {n}")
    memory_limit = parse_memory_limit(memory_limit)
    with (
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            # Any free port for the scheduler's HTTP server: with None it still takes 8787,
            # and a second cluster on the machine (another batch, a parallel test) warned.
            dashboard_address=":0",
            silence_logs=logging.ERROR,
            # Each worker's share of the machine: a log whose map outgrows it (an odometry
            # glitch, an absurd grid) has its worker restarted and fails as a row, instead
            # of the operating system killing whatever process it picks.
            memory_limit=memory_limit,
            preload=[WORKER_PRELOAD],
        ) as cluster,
        Client(cluster, set_as_default=False) as client,
    ):
        try:
            client.wait_for_workers(n, timeout=WORKERS_TIMEOUT_S)
        except TimeoutError as err:
            raise ConfigError(f"the {n} local Dask worker(s) did not start within "
                              f"{WORKERS_TIMEOUT_S:.0f} s") from err
        yield client


def run_batch(
    inputs: Sequence[Location],
    out_dir: Location,
    config_path: Path | None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    memory_limit: str | int = MEMORY_LIMIT,
    rerun: bool = False,
    progress: BatchProgress | None = None,
    manifests: Sequence[Path] = (),
) -> BatchResult:
    """Map every log of ``inputs`` (files, directories) and ``manifests`` into
    ``out_dir/<name>/``; write ``summary.parquet`` and ``summary.md``.

    Raises SonarmapError only for problems of the whole batch (bad configuration, no logs
    found, unreachable scheduler, unwritable output directory); a log's failure is a row.
    """
    from formats.storage.options import configure

    cfg = load_config(config_path)
    configure(cfg.storage)
    if scheduler is None:
        memory_limit = parse_memory_limit(memory_limit)
    out_dir = _absolute(out_dir)
    if isinstance(out_dir, Path) and out_dir.exists() and not out_dir.is_dir():
        raise OutputError("exists and is not a directory", out_dir)
    check_summary_replaceable(out_dir)
    unread: list[Unread] = []
    # OUT itself is searched too: a user's logs there are mapped (sonarmap's files are not
    # logs, :func:`_search`).
    logs = find_logs(inputs, cfg, manifests=manifests, unread=unread)
    if not logs:
        where = ", ".join(str(p) for p in [*inputs, *manifests]) or "(no inputs)"
        also = f" ({unread[0].path}: {unread[0].reason})" if unread else ""
        raise InputError(f"no logs found in {where}{also}")
    if isinstance(out_dir, Path):
        from formats.writers.atomic import clean_stale_entries, make_dir

        make_dir(out_dir, "output directory")

        # Staging left by interrupted batches (their processes are dead), whatever log it
        # was for; a concurrent batch's live staging stays.
        clean_stale_entries(out_dir)
    names = output_names(logs)
    # One thread per worker (mapper.threads = 1): the workers already share the cores.
    cfg_dict = cfg.replace(mapper=dataclasses.replace(cfg.mapper, threads=1)).to_dict()
    total = len(logs)
    rows: list[LogOutcome] = []
    if progress is not None:
        progress(0, total)
    with _client(workers, scheduler, memory_limit) as client:
        futures = {
            # URLs travel as given (a worker needs their credentials); never printed.
            client.submit(_map_one, [_wire(f) for f in log_files(p)], _wire(out_dir), names[p],
                          cfg_dict, rerun, pure=False,
                          key=f"sonarmap-{_utf8(names[p])}-{secrets.token_hex(4)}"): p
            for p in logs
        }
        try:
            for fut, stalled in _finished(client, list(futures)):
                p = futures[fut]
                rows.append(_collect(fut, p, names[p]) if stalled is None
                            else LogOutcome(log_text(p), names[p], "failed", error=stalled))
                if progress is not None:
                    progress(len(rows), total)
        except BaseException:
            client.cancel(list(futures))  # interrupted: finished logs keep their markers
            raise
    rows += [LogOutcome(str(u.path), u.path.name, "skipped", error=u.reason) for u in unread]
    rows.sort(key=lambda r: r.path)
    pq_path, md_path = write_summary(out_dir, rows)
    return BatchResult(out_dir, rows, pq_path, md_path)


def _wire(where: Location) -> str:
    return where.text if isinstance(where, Url) else str(where)


def _finished(client: Any, futures: list[Any]) -> Iterator[tuple[Any, str | None]]:
    """``(future, None)`` as each task finishes; when no worker can make progress for
    :data:`STALL_S` — every worker paused by Dask's memory limit with nothing executing,
    or none alive — ``(future, reason)`` for each task left (cancelled), so a batch never
    waits forever."""
    pending = list(futures)
    stalled_since: float | None = None
    looked = time.monotonic()
    while pending:
        done = [f.done() for f in pending]
        for fut, d in zip(pending, done, strict=True):
            if d:
                yield fut, None
        pending = [f for f, d in zip(pending, done, strict=True) if not d]
        done_any = any(done)
        now = time.monotonic()
        if done_any or not pending:
            stalled_since = None
            continue
        time.sleep(POLL_S)
        if now - looked < WATCH_S:
            continue
        looked = now
        reason = _stall_reason(client)
        if reason is None:
            stalled_since = None
            continue
        stalled_since = now if stalled_since is None else stalled_since
        if now - stalled_since >= STALL_S:
            client.cancel(list(pending))
            for fut in sorted(pending, key=lambda f: str(f.key)):
                yield fut, reason
            return


def _stall_reason(client: Any) -> str | None:
    """Why no worker can run a task now, or None when one can."""
    from dask.utils import format_bytes

    workers = client.scheduler_info().get("workers", {}).values()
    if not workers:
        return "no Dask worker stayed alive to map it (killed at its memory limit?)"
    for w in workers:
        executing = w.get("metrics", {}).get("task_counts", {}).get("executing", 0)
        if w.get("status") == "running" or executing:
            return None
    w = next(iter(workers))
    return (f"no Dask worker could start it: a worker holds {format_bytes(w['metrics']['memory'])}"
            f" before any log, above the pause threshold of its memory limit "
            f"{format_bytes(w['memory_limit'])}; give a larger --memory-limit")


def _collect(fut: Any, path: LogInput, name: str) -> LogOutcome:
    """A finished task's outcome; a task that died (worker killed) is a failed row."""
    try:
        d = fut.result()
    except Exception as err:
        log.error("%s: task failed on the cluster: %s: %s", log_text(path), type(err).__name__,
                  err)
        return LogOutcome(log_text(path), name, "failed",
                          error=" ".join(f"{type(err).__name__}: {err}".split()))
    tb = d.pop("traceback", None)
    if tb:
        log.error("%s: unexpected error while mapping\n%s", log_text(path), tb.rstrip())
    return LogOutcome.from_dict(d)


# --------------------------------------------------------------------------- summary


def summary_table(rows: Sequence[LogOutcome]) -> Any:
    """The summary as a pyarrow Table (one row per log, in the given order)."""
    import pyarrow as pa

    schema = pa.schema([
        pa.field("path", pa.string(), nullable=False),
        pa.field("name", pa.string(), nullable=False),
        pa.field("status", pa.string(), nullable=False),
        pa.field("error", pa.string()),
        pa.field("duration_s", pa.float64(), metadata={"unit": "s"}),
        pa.field("readings", pa.int64()),
        pa.field("features", pa.int64()),
        pa.field("mean_feature_variance_m2", pa.float64(), metadata={"unit": "m^2"}),
        pa.field("mapped_area_m2", pa.float64(), metadata={"unit": "m^2"}),
        pa.field("seconds", pa.float64(), nullable=False, metadata={"unit": "s"}),
        pa.field("warnings", pa.string()),
    ])
    cols = {f.name: [_utf8(getattr(r, f.name)) for r in rows] for f in schema}
    return pa.table(cols, schema=schema)


def _utf8(v: Any) -> Any:
    """A string Arrow can hold: a file name's non-UTF-8 bytes (surrogate-escaped) as
    ``\\udcXX`` text, as the Markdown summary shows them."""
    if isinstance(v, str):
        return v.encode("utf-8", errors="backslashreplace").decode("utf-8")
    return v


def check_summary_replaceable(out_dir: Location) -> None:
    """Refuse (OutputError, before any work) a ``summary.md`` or ``summary.parquet`` in
    ``out_dir`` that sonarmap did not write: a batch replaces only its own summaries (under
    a URL prefix: judged by the same rule, :func:`output_marker.stamped`, on its bytes)."""
    from formats.writers.output_marker import not_replaceable_file_reason, stamped

    if isinstance(out_dir, Url):
        from formats.writers.remote_output import url_reader

        for name, kind in ((SUMMARY_MD, "summary_md"), (SUMMARY_PARQUET, "summary_parquet")):
            if (out_dir / name).exists() and not stamped(kind, name, url_reader(out_dir)):
                raise OutputError("exists and sonarmap did not write it; not replacing it "
                                  "with the batch summary, choose another output prefix",
                                  out_dir / name)
        return
    for name, kind in ((SUMMARY_MD, "summary_md"), (SUMMARY_PARQUET, "summary_parquet")):
        p = out_dir / name
        if p.exists() or p.is_symlink():
            reason = not_replaceable_file_reason(p, kind)
            if reason is not None:
                raise OutputError(f"{reason}; not replacing it with the batch summary, "
                                  "choose another output directory", p)


def write_summary(out_dir: Location, rows: Sequence[LogOutcome]) -> tuple[Location, Location]:
    """Write ``summary.parquet`` and ``summary.md`` atomically (under a URL prefix: each
    object appears whole or not at all); return their locations. Only summaries sonarmap
    wrote are replaced (:func:`check_summary_replaceable`, again: a file may have appeared
    while the logs were mapped)."""
    import pyarrow.parquet as pq

    from formats.writers.atomic import atomic_write_bytes, atomic_write_text

    check_summary_replaceable(out_dir)
    buf = io.BytesIO()
    pq.write_table(summary_table(rows), buf, compression="zstd")
    if isinstance(out_dir, Url):
        fs = out_dir.fs
        for name, data in ((SUMMARY_PARQUET, buf.getvalue()),
                           (SUMMARY_MD, summary_markdown(rows).encode())):
            target = out_dir / name

            def put(t: Url = target, d: bytes = data) -> None:
                fs.pipe_file(t.fs_path, d)

            target.call("cannot upload", put)
        return out_dir / SUMMARY_PARQUET, out_dir / SUMMARY_MD
    pq_path, md_path = out_dir / SUMMARY_PARQUET, out_dir / SUMMARY_MD
    atomic_write_bytes(pq_path, buf.getvalue())
    atomic_write_text(md_path, summary_markdown(rows))
    return pq_path, md_path


def summary_markdown(rows: Sequence[LogOutcome]) -> str:
    """The summary as a Markdown document with one table row per log."""
    counts = {s: sum(r.status == s for r in rows) for s in ("ok", "skipped", "failed")}
    unread = sum(r.status == "skipped" and r.error is not None for r in rows)
    lines = [
        SUMMARY_MD_TITLE,
        "",
        f"{len(rows)} logs: {counts['ok']} mapped, {counts['skipped'] - unread} skipped "
        f"(unchanged), {counts['failed']} failed"
        + (f", {unread} directories not read." if unread else "."),
        "",
    ]
    header = ["log", "status", "duration (s)", "readings", "features",
              "mean feature variance (m²)", "mapped area (m²)", "wall (s)", "path", "error",
              "warnings"]
    cells = [
        [
            r.name, r.status, _fmt(r.duration_s, ".1f"), _fmt(r.readings, "d"),
            _fmt(r.features, "d"), _fmt(r.mean_feature_variance_m2, ".4g"),
            _fmt(r.mapped_area_m2, ".2f"), _fmt(r.seconds, ".2f"), r.path, r.error or "",
            r.warnings or "",
        ]
        for r in rows
    ]
    lines += markdown_table(header, cells, right=range(2, 8))
    return "\n".join(lines) + "\n"


def _fmt(v: float | int | None, spec: str) -> str:
    return "" if v is None else format(v, spec)
