"""CSV / plain-text sonar logs: the reader and format sniffing.

Schema (``[input.csv]`` in the configuration, :class:`formats.options.CsvConfig`)
-------------------------------------------------------------------------------
Two shapes, chosen by ``layout``:

* **single** (default): one file, a row per reading, header ``t,x,y,yaw,sensor,range``
  and optionally ``fov,min_range,max_range,scan`` (any column order; header names are
  matched case-insensitively; unknown columns are ignored). ``t`` = reading time,
  ``x,y,yaw`` = robot pose (base frame in the odom/world frame) at ``t``, ``sensor`` =
  sensor name, ``range`` = measured distance; ``inf``, ``-inf`` and ``nan`` are allowed in
  ``range`` (REP 117). Optional ``fov`` (full beam width), ``min_range``, ``max_range`` per
  row (an empty field = not given); ``scan`` (integer) groups readings into scans for the
  ``explicit`` scan policy. Poses are the distinct ``(t, x, y, yaw)`` rows.
* **set**: the log path is a directory (or one of its files) holding ``ranges_file``
  (default ``ranges.csv``: ``t,sensor,range[,fov,min_range,max_range,scan]``, or with
  ``wide_ranges = true`` ``t,<one column per sensor>`` — the header names the sensors;
  without a header they are ``sonar_0 … sonar_{n-1}``; each row is one scan),
  ``poses_file`` (default ``poses.csv``: ``t,x,y,yaw``) and optionally ``sensors_file``
  (default ``sensors.csv``: ``sensor,x,y,yaw[,fov,min_range,max_range]``, mounts in the
  base frame).

Options: ``delimiter`` (``,`` default; ``whitespace`` = runs of blanks; double quotes are
honoured for one-character delimiters), ``header`` (without one the columns are in the
order listed above; a file may stop after the required ones), ``time_unit``
``s``/``ms``/``us``/``ns`` (converted to int64 ns exactly, from the decimal text),
``length_unit`` ``m``/``cm``/``mm`` (x, y, range, min/max range), ``angle_unit``
``rad``/``deg``/``tenths`` (yaw, fov, mount yaw; tenths of a degree), ``no_echo_value``
(a range equal to it, in ``length_unit``, becomes ``+inf``; negative or NaN = none).
Lines starting with ``#`` and blank lines are ignored. Files are UTF-8.

Beam limits a row does not carry come from ``sensors.csv``, else the sensor's
``[[sensors.mounts]]``/preset entry (non-zero values), else the ``[sensors]`` defaults,
else NaN (the pipeline decides). Every malformed row is a :class:`FormatError` naming the
file and line. NaN/inf ranges are data; NaN/inf in ``t, x, y, yaw`` is an error. Rows are
yielded in file order (unsorted time is the pipeline's business). Order of batches: single
layout — per chunk, poses then ranges; set layout — mounts, all poses, then all ranges.
"""

from __future__ import annotations

import codecs
import csv
import itertools
import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I64, Strs
from formats.contract import (
    ALL_KINDS,
    Batch,
    Kind,
    LogInfo,
    MountBatch,
    PoseBatch,
    RangeBatch,
    SensorMount,
    TopicInfo,
    make_range_batch,
)
from formats.errors import FormatError
from formats.options import MAX_NAME_CHARS, CsvConfig, ReaderSettings
from formats.ranges import ANGLE_RAD, COORD_M, LIMIT_M, MOUNT_M, Range
from formats.sensor_config import BeamLimits, sensor_setup
from formats.stamps import parse_time
from formats.storage.location import Location, as_location

CHUNK_BYTES = 4 << 20  # bytes of text per chunk (about 60 000 rows of a typical log)
# A field is a number or a sensor name: longer is no field (and would make every string
# array of its chunk that wide).
MAX_FIELD_CHARS = MAX_NAME_CHARS
SCAN_ID = Range(-(2**63), 2**63 - 1)  # int64, as scans are numbered
POSE_PARENT_FRAME = "odom"

_TIME_DIGITS = {"s": 9, "ms": 6, "us": 3, "ns": 0}  # decimal digits of a unit below 1 ns
_LENGTH_DIV = {"m": 1.0, "cm": 100.0, "mm": 1000.0}  # divide (exact for integers) to get m
_ANGLE_MUL = {"rad": 1.0, "deg": math.pi / 180.0, "tenths": math.pi / 1800.0}

# Column order of each table (required columns first); a file without a header may stop
# after the required ones.
_SINGLE = (("t", "x", "y", "yaw", "sensor", "range"), ("fov", "min_range", "max_range", "scan"))
_RANGES = (("t", "sensor", "range"), ("fov", "min_range", "max_range", "scan"))
_POSES = (("t", "x", "y", "yaw"), ())
_SENSORS = (("sensor", "x", "y", "yaw"), ("fov", "min_range", "max_range"))


# --------------------------------------------------------------------------- sniffing


def looks_like_csv(path: str | Location, config: ReaderSettings | None = None) -> bool:
    """Whether ``path`` looks like a CSV log (content sniffing, for format detection).

    A file: UTF-8 text without NUL bytes whose first non-comment line splits into at
    least two fields by the configured delimiter, a comma or whitespace. A directory:
    holds the default ``ranges.csv`` and ``poses.csv``, or the configured file names.
    """
    p = as_location(path)
    if p.is_dir():
        names = [("ranges.csv", "poses.csv")]
        if config is not None:
            c = config.input.csv
            names.append((c.ranges_file, c.poses_file))
        return any((p / r).is_file() and (p / q).is_file() for r, q in names)
    try:
        with p.open("rb") as f:
            head = f.read(65_536)
    except OSError:
        return False
    if not head or b"\x00" in head:
        return False
    try:
        # An incremental decoder tolerates a multi-byte character cut at the 64 KiB mark.
        text = codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        return False
    delimiters = [","]
    if config is not None and config.input.csv.delimiter != "whitespace":
        delimiters.append(config.input.csv.delimiter)
    for line in text.splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        splits = [s.split()] + [s.split(d) for d in delimiters]
        return any(len(f) >= 2 and all(_CSV_FIELD.fullmatch(x.strip().strip('"')) for x in f)
                   for f in splits)
    return False


# A header or data field of a CSV log: a column name or a number (prose and markup are not).
_CSV_FIELD = re.compile(r"[\w.+\-/()\[\]%° ]*")


# --------------------------------------------------------------------------- table reading


@dataclass
class _Chunk:
    """Data rows of about CHUNK_BYTES of one file: physical line numbers and string columns."""

    lines: I64
    cols: dict[str, list[str]]  # raw fields (blanks and line ends not yet stripped)

    def __len__(self) -> int:
        return int(self.lines.shape[0])

    def strings(self, name: str) -> Strs:
        """A column as a numpy string array, blanks stripped."""
        return np.strings.strip(np.array(self.cols[name], dtype=np.str_))


class _Table:
    """One CSV file read as a stream of string-column chunks, with line numbers."""

    def __init__(
        self,
        path: Location,
        csv_cfg: CsvConfig,
        columns: tuple[tuple[str, ...], tuple[str, ...]] | None,
    ) -> None:
        self.path = path
        self.cfg = csv_cfg
        self.columns = columns  # None = wide ranges: t + one column per sensor
        self.names: list[str] = []  # column names in file order
        self.rows = 0  # data rows met so far

    def error(self, line: int, what: str) -> FormatError:
        return FormatError(f"line {line}: {what}", self.path)

    def chunks(self) -> Iterator[_Chunk]:
        """The file's data rows, a block of about CHUNK_BYTES at a time (header consumed)."""
        self.rows = 0
        try:
            f = self.path.open("rb")
        except OSError as err:
            raise FormatError(f"cannot read: {err.strerror or err}", self.path) from err
        with f:
            yield from self._chunks(f)

    def _blocks(self, f: BinaryIO) -> Iterator[tuple[bytes, int]]:
        """Whole lines, about CHUNK_BYTES at a time, with the number of their first line."""
        carry = b""
        line = 1
        head = True
        while True:
            try:
                data = f.read(CHUNK_BYTES)
            except OSError as err:
                raise self.error(line, f"cannot read: {err.strerror or err}") from err
            if head:
                head = False
                data = data.removeprefix(b"\xef\xbb\xbf")  # UTF-8 byte order mark
            if not data:
                if carry:
                    yield carry, line
                return
            buf = carry + data
            cut = buf.rfind(b"\n") + 1
            if cut == 0:  # a line longer than a block: read on
                carry = buf
                continue
            block, carry = buf[:cut], buf[cut:]
            yield block, line
            line += block.count(b"\n")

    def _chunks(self, f: BinaryIO) -> Iterator[_Chunk]:
        ncols = -1
        first = True
        for block, line0 in self._blocks(f):
            try:
                text = block.decode("utf-8")
            except UnicodeDecodeError as err:
                line = line0 + block.count(b"\n", 0, err.start)
                raise self.error(line, f"not UTF-8 text ({err.reason})") from err
            text = text.removesuffix("\n")
            data = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
            nums = np.arange(line0, line0 + text.count("\n") + 1, dtype=np.int64)
            keep = _data_lines(data, nums.shape[0])
            if not keep.all():
                # Comments or blank lines in this block: drop them (rare, so done per line).
                lines = list(itertools.compress(text.split("\n"), keep.tolist()))
                if not lines:
                    continue
                nums = nums[keep]
                text = "\n".join(lines)
                data = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
            if first:
                first = False
                head_line, _, rest = text.partition("\n")
                fields = self._split_lines([head_line], nums[:1])[0]
                if not self.cfg.header:  # the first row is data and sets the column count
                    ncols = self._set_positional(fields, int(nums[0]))
                else:
                    ncols = self._set_header(fields, int(nums[0]))
                    text, nums = rest, nums[1:]
                    data = data[len(head_line.encode("utf-8")) + 1 :]
                    if not nums.size:
                        continue
            cols = self._columns(text, data, nums, ncols)
            self.rows += int(nums.shape[0])
            yield _Chunk(nums, cols)
        if first:
            raise FormatError(
                "empty file: no header and no data rows"
                if self.cfg.header
                else "empty file: no data rows",
                self.path,
            )

    def _columns(
        self, text: str, data: npt.NDArray[np.uint8], nums: I64, ncols: int
    ) -> dict[str, list[str]]:
        """Split lines into fields (one C-level split for the whole block where possible)."""
        d = self.cfg.delimiter
        n = int(nums.shape[0])
        quoted = d != "whitespace" and len(d) == 1 and b'"'[0] in data
        counts = _field_counts(data, n, d) if not quoted else None
        if counts is None:
            rows = self._split_lines(text.split("\n"), nums)
            counts = np.fromiter(map(len, rows), dtype=np.int64, count=n)
            self._check_counts(counts, nums, ncols)
            flat = [field for row in rows for field in row]
        else:
            self._check_counts(counts, nums, ncols)
            flat = text.split() if d == "whitespace" else text.replace("\n", d).split(d)
        cols = {
            name: flat[j::ncols] for j, name in enumerate(self.names) if not name.startswith("\0")
        }
        for name, col in cols.items():
            # Before any numpy string array: its width is the longest field's, times rows.
            if col and max(map(len, col)) > MAX_FIELD_CHARS:
                i = next(i for i, f in enumerate(col) if len(f) > MAX_FIELD_CHARS)
                raise self.error(int(nums[i]), f"column '{name}': a field of {len(col[i])}"
                                 f" characters (a number or name has at most {MAX_FIELD_CHARS})")
        return cols

    def _check_counts(self, counts: I64, nums: I64, ncols: int) -> None:
        bad = np.flatnonzero(counts != ncols)
        if bad.size:
            i = int(bad[0])
            raise self.error(
                int(nums[i]),
                f"expected {ncols} fields ({','.join(self._shown())}), found {counts[i]}",
            )

    def _shown(self) -> list[str]:
        return [n if not n.startswith("\0") else "?" for n in self.names]

    def _split_lines(self, lines: list[str], numbers: I64) -> list[list[str]]:
        """Fields of each line (keeping blanks and line ends: columns are stripped later)."""
        d = self.cfg.delimiter
        if d == "whitespace":
            return [ln.split() for ln in lines]
        if len(d) != 1:
            return [ln.split(d) for ln in lines]
        reader = csv.reader(lines, delimiter=d, skipinitialspace=True, strict=True)
        try:
            rows = list(reader)
        except csv.Error as err:
            line = int(numbers[reader.line_num - 1])
            raise self.error(line, f"malformed CSV: {err}") from err
        if len(rows) != len(lines):
            # A quoted field ran over a line end: fields would no longer match line numbers.
            raise self.error(int(numbers[0]), "malformed CSV: a quoted field spans lines")
        return rows

    def _set_header(self, fields: list[str], line: int) -> int:
        names = [s.strip() for s in fields]
        low = [s.lower() for s in names]
        long = [n for n in names if len(n) > MAX_FIELD_CHARS]
        if long:
            raise self.error(line, f"a header name of {len(long[0])} characters (at most"
                                   f" {MAX_FIELD_CHARS})")
        if self.columns is None:  # wide ranges: t, then the sensor names (case kept)
            if len(names) < 2 or low[0] != "t":
                raise self._header_error(names, line, "a header 't,<sensor>,<sensor>,...'")
            dup = sorted({n for n in names[1:] if names[1:].count(n) > 1})
            if dup or any(not n for n in names[1:]):
                raise self.error(line, f"duplicate or empty sensor names in header: {dup}")
            self.names = ["t", *names[1:]]
            return len(names)
        required, optional = self.columns
        missing = [c for c in required if c not in low]
        if missing:
            raise self._header_error(names, line, f"column '{missing[0]}'")
        dup = sorted({n for n in low if n and low.count(n) > 1})
        if dup:
            raise self.error(line, f"duplicate column {dup[0]!r} in header")
        known = set(required) | set(optional)
        # Unknown columns are skipped (a NUL-prefixed name can never clash with a real one).
        self.names = [n if n in known else f"\0{j}" for j, n in enumerate(low)]
        return len(names)

    def _header_error(self, names: list[str], line: int, expected: str) -> FormatError:
        if names and _is_number(names[0]):
            return self.error(
                line,
                f"no header: the first line {','.join(names)!r} looks like data "
                "(set [input.csv] header = false, or add a header)",
            )
        return self.error(line, f"missing required {expected} in header {','.join(names)!r}")

    def _set_positional(self, fields: list[str], line: int) -> int:
        n = len(fields)
        if self.columns is None:
            if n < 2:
                raise self.error(line, f"expected t and at least one range column, found {n} field")
            self.names = ["t", *(f"sonar_{i}" for i in range(n - 1))]
            return n
        required, optional = self.columns
        order = required + optional
        if not len(required) <= n <= len(order):
            raise self.error(
                line,
                f"expected {len(required)} to {len(order)} fields ({','.join(order)}), found {n}",
            )
        self.names = list(order[:n])
        return n


_BLANKS = np.array([ord(c) for c in " \t\r\f\v"], dtype=np.uint8)
_NL = ord("\n")


def _data_lines(data: npt.NDArray[np.uint8], n: int) -> npt.NDArray[np.bool_]:
    """Per line of a block: True unless blank or a comment (first non-blank byte '#')."""
    if not data.size:
        return np.zeros(n, dtype=bool)
    nl = np.flatnonzero(data == _NL)
    starts = np.concatenate(([0], nl + 1))
    ends = np.append(nl, data.shape[0])
    first = data[np.minimum(starts, data.shape[0] - 1)]
    keep = np.ones(n, dtype=bool)
    # Only lines that start empty, blank or with '#' need a closer look.
    odd = np.flatnonzero((starts >= ends) | np.isin(first, _BLANKS) | (first == ord("#")))
    if odd.size:
        solid = np.flatnonzero(~np.isin(data, _BLANKS) & (data != _NL))
        k = np.searchsorted(solid, starts[odd])
        pos = solid[np.minimum(k, solid.shape[0] - 1)] if solid.size else starts[odd]
        has = (k < solid.shape[0]) & (pos < ends[odd])
        keep[odd] = has & (data[np.minimum(pos, data.shape[0] - 1)] != ord("#"))
    return keep


def _field_counts(data: npt.NDArray[np.uint8], n: int, delimiter: str) -> I64 | None:
    """Fields per line, counted on the bytes; None for delimiters that need per-line work."""
    nl = np.flatnonzero(data == _NL)
    if delimiter == "whitespace":
        solid = ~np.isin(data, _BLANKS) & (data != _NL)
        hits = np.flatnonzero(solid & ~np.concatenate(([False], solid[:-1])))  # token starts
        return np.bincount(np.searchsorted(nl, hits), minlength=n).astype(np.int64)
    if len(delimiter) != 1 or ord(delimiter) > 127:
        return None
    hits = np.flatnonzero(data == ord(delimiter))
    return np.bincount(np.searchsorted(nl, hits), minlength=n).astype(np.int64) + 1


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _floats(
    table: _Table, chunk: _Chunk, name: str, *, finite: bool, optional: bool = False
) -> F64:
    """A column as float64. ``optional``: empty fields are NaN. ``finite``: NaN/inf is an error."""
    raw = chunk.cols[name]
    try:
        # float() parses in C, ignores surrounding blanks and knows inf/nan (REP 117).
        v = np.fromiter(map(float, raw), dtype=np.float64, count=len(raw))
    except ValueError:
        s = chunk.strings(name)
        if optional:
            s = np.where(s == "", "nan", s)
        try:
            v = s.astype(np.float64)
        except ValueError:
            for i, text in enumerate(s.tolist()):
                if not _is_number(text):
                    what = "an empty field" if text == "" else repr(text)
                    raise table.error(
                        int(chunk.lines[i]), f"column '{name}': expected a number, found {what}"
                    ) from None
            raise  # pragma: no cover - numpy and float() disagree
    if finite:
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            i = int(bad[0])
            raise table.error(
                int(chunk.lines[i]),
                f"column '{name}': {raw[i].strip()!r} is not a finite number",
            )
    return v


def _times_ns(table: _Table, chunk: _Chunk, name: str) -> I64:
    """A time column as int64 ns, converted exactly from its decimal text.

    Digits below 1 ns are rounded half away from zero; exponent notation (``1.5e9``) is
    accepted through Python's Decimal on the rows that need it.
    """
    unit = table.cfg.time_unit
    k = _TIME_DIGITS[unit]
    s = chunk.strings(name)
    unsigned = np.strings.lstrip(s, "+-")
    sign_len = np.strings.str_len(s) - np.strings.str_len(unsigned)
    neg = np.strings.startswith(s, "-")
    ip, _, fp = np.strings.partition(unsigned, ".")
    ok = (
        (sign_len <= 1)
        & (np.strings.isdecimal(ip) | (ip == ""))
        & (np.strings.isdecimal(fp) | (fp == ""))
        & ((ip != "") | (fp != ""))
    )
    # ip * 10**k + fraction must fit int64; longer or larger integer parts go the slow way.
    limit = str((2**63 - 1) // 10**k - 1)
    ip_len = np.strings.str_len(ip)
    ok &= (ip_len < len(limit)) | ((ip_len == len(limit)) & (ip <= limit))
    # The first k + 1 fraction digits as numbers (astype to U{k+1} cuts the rest off).
    padded = np.strings.ljust(fp, k + 1, "0").astype(f"<U{k + 1}")
    digits = padded.view(np.uint32).reshape(-1, k + 1).astype(np.int64) - ord("0")
    # isdecimal() also accepts non-ASCII digits; those go the slow, exact way.
    ok &= ((digits >= 0) & (digits <= 9)).all(axis=1)
    out = np.zeros(s.shape[0], dtype=np.int64)
    if ok.any():
        ipv = np.where(ip == "", "0", ip)[ok].astype(np.int64)
        digits = digits[ok]
        frac = np.zeros(ipv.shape[0], dtype=np.int64)
        if k:
            frac = digits[:, :k] @ (10 ** np.arange(k - 1, -1, -1, dtype=np.int64))
        mag = ipv * 10**k + frac + (digits[:, k] >= 5)
        out[ok] = np.where(neg[ok], -mag, mag)
    for i in np.flatnonzero(~ok).tolist():
        out[i] = _time_slow(table, int(chunk.lines[i]), name, str(s[i]), k)
    return out


def _time_slow(table: _Table, line: int, name: str, text: str, k: int) -> int:
    try:
        return parse_time(text, digits=k)
    except ValueError as err:
        raise table.error(line, f"column '{name}': {err}") from None


def _sensor_column(table: _Table, chunk: _Chunk) -> Strs:
    s = chunk.strings("sensor")
    empty = np.flatnonzero(s == "")
    if empty.size:
        raise table.error(int(chunk.lines[int(empty[0])]), "column 'sensor': empty sensor name")
    return s


def _scan_column(table: _Table, chunk: _Chunk) -> I64:
    s = chunk.strings("scan")
    s = np.where(s == "", "-1", s)
    try:
        return s.astype(np.int64)
    except (ValueError, OverflowError):
        for i, text in enumerate(s.tolist()):
            try:
                value = int(text)
            except ValueError:
                raise table.error(
                    int(chunk.lines[i]), f"column 'scan': expected an integer, found {text!r}"
                ) from None
            if not SCAN_ID.holds(value):
                raise table.error(int(chunk.lines[i]),
                                  f"column 'scan': {text} {SCAN_ID.rule()}") from None
        raise  # pragma: no cover


def _check_column(table: _Table, chunk: _Chunk, name: str, v: F64, rng: Range) -> F64:
    """``v`` (a column in sonarmap's units), every value given (not NaN) within ``rng``."""
    bad = np.flatnonzero(~np.isnan(v) & ~((v >= rng.lo) & (v <= rng.hi)))
    if bad.size:
        i = int(bad[0])
        raise table.error(int(chunk.lines[i]),
                          f"column '{name}': {chunk.cols[name][i].strip()} {rng.rule()}")
    return v


# --------------------------------------------------------------------------- the reader


class CsvLogReader:
    """A CSV/text sonar log (see the module docstring for the schema), as a LogReader."""

    format_name = "csv"

    def __init__(self, path: str | Location, config: ReaderSettings) -> None:
        self.path = as_location(path)
        self.config = config
        self.csv = config.input.csv
        self.sensor_names: list[str] = []
        self._ids: dict[str, int] = {}
        self._info: LogInfo | None = None
        self._closed = False
        c = self.csv
        for key, value, known in (
            ("time_unit", c.time_unit, _TIME_DIGITS),
            ("length_unit", c.length_unit, _LENGTH_DIV),
            ("angle_unit", c.angle_unit, _ANGLE_MUL),
        ):
            if value not in known:
                raise FormatError(
                    f"unknown {key} {value!r} in [input.csv] (expected one of {', '.join(known)})",
                    self.path,
                )
        if not self.path.exists():
            raise FormatError("no such file or directory", self.path)
        self._len_div = _LENGTH_DIV[c.length_unit]
        self._ang_mul = _ANGLE_MUL[c.angle_unit]
        self._no_echo = c.no_echo_value if c.no_echo_value >= 0 else math.nan
        self._sensor_setup = sensor_setup(config.sensors)
        self._log_limits: dict[str, tuple[float, float, float]] = {}
        self._mounts: dict[str, SensorMount] | None = None
        # A directory can only be a set of files: read it as one whatever `layout` says.
        self.layout = "set" if self.path.is_dir() else c.layout
        if self.layout == "set":
            folder = self.path if self.path.is_dir() else self.path.parent
            self.ranges_path = folder / c.ranges_file
            self.poses_path: Location | None = folder / c.poses_file
            sensors = folder / c.sensors_file
            self.sensors_path: Location | None = sensors if sensors.is_file() else None
            for p in (self.ranges_path, self.poses_path):
                if not p.is_file():
                    raise FormatError(
                        f"CSV log set has no {p.name} (set [input.csv] ranges_file/poses_file)",
                        folder,
                    )
        elif self.layout == "single":
            self.ranges_path, self.poses_path, self.sensors_path = self.path, None, None
        else:
            raise FormatError(f"unknown [input.csv] layout {c.layout!r}", self.path)

    # -- context manager -------------------------------------------------------------

    def __enter__(self) -> CsvLogReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Nothing stays open between calls; marks the reader closed."""
        self._closed = True

    # -- LogReader ----------------------------------------------------------------------

    def info(self) -> LogInfo:
        """Format, time span, rows per file and the sensors found (reads the log once)."""
        if self._info is None:
            self._info = self._scan_info()
        return self._info

    def batches(self, kinds: Sequence[Kind] = ALL_KINDS) -> Iterator[Batch]:
        """Stream the log in chunks of about CHUNK_BYTES of text each, in file order."""
        for _, _, batch in self._stream(kinds):
            yield batch

    # -- internals ----------------------------------------------------------------------

    def _stream(self, kinds: Sequence[Kind]) -> Iterator[tuple[str, int, Batch]]:
        """(file name, file rows the batch stands for, batch). Single layout: pose batches
        stand for no rows of their own (the rows are the readings)."""
        if self._closed:
            raise FormatError("reader is closed", self.path)
        want = set(kinds)
        if self.layout == "single":
            yield from self._single(want)
            return
        mounts = self._load_sensors()
        if "mounts" in want and self.sensors_path is not None:
            yield (
                self.sensors_path.name,
                len(mounts),
                MountBatch(self.config.input.base_frame, dict(mounts)),
            )
        if "poses" in want and self.poses_path is not None:
            table = _Table(self.poses_path, self.csv, _POSES)
            for chunk in table.chunks():
                yield self.poses_path.name, len(chunk), self._poses(table, chunk)
        if "ranges" in want:
            wide = self.csv.wide_ranges
            table = _Table(self.ranges_path, self.csv, None if wide else _RANGES)
            for chunk in table.chunks():
                if wide:
                    batch = self._wide_ranges(table, chunk, table.rows - len(chunk))
                else:
                    batch = self._long_ranges(table, chunk)
                yield self.ranges_path.name, len(chunk), batch

    def _single(self, want: set[Kind]) -> Iterator[tuple[str, int, Batch]]:
        table = _Table(self.ranges_path, self.csv, _SINGLE)
        name = self.ranges_path.name
        last: I64 | None = None  # key of the last pose yielded, to drop a repeat across chunks
        for chunk in table.chunks():
            rows = len(chunk)
            t = _times_ns(table, chunk, "t")  # parsed once for poses and ranges
            if "poses" in want:
                poses = self._poses(table, chunk, t)
                keys = np.stack(
                    [
                        poses.t_ns,
                        poses.x.view(np.int64),
                        poses.y.view(np.int64),
                        poses.yaw.view(np.int64),
                    ],
                    axis=1,
                )
                _, first = np.unique(keys, axis=0, return_index=True)
                first.sort()
                if last is not None and first.size and np.array_equal(keys[first[0]], last):
                    first = first[1:]
                if first.size:
                    last = keys[first[-1]]
                    yield (
                        name,
                        0,
                        PoseBatch(
                            poses.t_ns[first],
                            poses.x[first],
                            poses.y[first],
                            poses.yaw[first],
                            poses.parent_frame,
                            poses.child_frame,
                        ),
                    )
            if "ranges" in want:
                yield name, rows, self._long_ranges(table, chunk, t)

    def _poses(self, table: _Table, chunk: _Chunk, t: I64 | None = None) -> PoseBatch:
        t = _times_ns(table, chunk, "t") if t is None else t
        x = _check_column(table, chunk, "x", _floats(table, chunk, "x", finite=True)
                          / self._len_div, COORD_M)
        y = _check_column(table, chunk, "y", _floats(table, chunk, "y", finite=True)
                          / self._len_div, COORD_M)
        yaw = _check_column(table, chunk, "yaw", _floats(table, chunk, "yaw", finite=True)
                            * self._ang_mul, ANGLE_RAD)
        return PoseBatch(t, x, y, yaw, POSE_PARENT_FRAME, self.config.input.base_frame)

    def _ranges_m(self, raw: F64) -> F64:
        # Compare in the file's unit, before any rounding by the unit conversion.
        out = raw / self._len_div
        if not math.isnan(self._no_echo):
            out[raw == self._no_echo] = np.inf
        return out

    def _long_ranges(self, table: _Table, chunk: _Chunk, t: I64 | None = None) -> RangeBatch:
        t = _times_ns(table, chunk, "t") if t is None else t
        names = _sensor_column(table, chunk)
        sid = self._sensor_ids(names)
        rng = self._ranges_m(_floats(table, chunk, "range", finite=False))
        fov_d, lo_d, hi_d = self._limit_table()
        fov, lo, hi = fov_d[sid], lo_d[sid], hi_d[sid]
        cols = chunk.cols
        if "fov" in cols:
            v = _floats(table, chunk, "fov", finite=False, optional=True) * self._ang_mul
            fov = np.where(np.isnan(v), fov, v)
        if "min_range" in cols:
            v = _floats(table, chunk, "min_range", finite=False, optional=True) / self._len_div
            lo = np.where(np.isnan(v), lo, _check_column(table, chunk, "min_range", v, LIMIT_M))
        if "max_range" in cols:
            v = _floats(table, chunk, "max_range", finite=False, optional=True) / self._len_div
            hi = np.where(np.isnan(v), hi, _check_column(table, chunk, "max_range", v, LIMIT_M))
        scan = _scan_column(table, chunk) if "scan" in cols else None
        return make_range_batch(t, sid, rng, fov, lo, hi, scan_id=scan)

    def _wide_ranges(self, table: _Table, chunk: _Chunk, first_row: int) -> RangeBatch:
        t = _times_ns(table, chunk, "t")
        sensors = table.names[1:]
        sid_row = self._sensor_ids(np.array(sensors, dtype=np.str_))
        raw = np.stack([_floats(table, chunk, s, finite=False) for s in sensors], axis=1)
        n, m = raw.shape
        fov_d, lo_d, hi_d = self._limit_table()
        sid = np.tile(sid_row, n)
        return make_range_batch(
            np.repeat(t, m),
            sid,
            self._ranges_m(raw.reshape(-1)),
            fov_d[sid],
            lo_d[sid],
            hi_d[sid],
            # One row carries the whole ring: it is one scan.
            scan_id=np.repeat(np.arange(first_row, first_row + n, dtype=np.int64), m),
        )

    def _sensor_ids(self, names: Strs) -> npt.NDArray[np.int32]:
        uniq, first, inverse = np.unique(names, return_index=True, return_inverse=True)
        # New sensors get ids in order of first appearance, so ids follow the file.
        for j in np.argsort(first, kind="stable").tolist():
            name = str(uniq[j])
            if name not in self._ids:
                self._ids[name] = len(self.sensor_names)
                self.sensor_names.append(name)
        lut = np.array([self._ids[str(u)] for u in uniq.tolist()], dtype=np.int32)
        return lut[inverse.reshape(-1)]

    def _limit_table(self) -> tuple[F64, F64, F64]:
        """fov, r_min, r_max per sensor id where a row carries none (NaN = unknown)."""
        rows = []
        for name in self.sensor_names:
            log = BeamLimits(*self._log_limits.get(name, (math.nan,) * 3))
            rows.append(log.or_else(self._sensor_setup.configured_limits(name)).as_tuple())
        arr = np.array(rows, dtype=np.float64).reshape(-1, 3)
        return arr[:, 0].copy(), arr[:, 1].copy(), arr[:, 2].copy()

    def _load_sensors(self) -> dict[str, SensorMount]:
        """Mounts from sensors.csv (read once; its fov/min/max become per-sensor defaults)."""
        if self._mounts is not None:
            return self._mounts
        mounts: dict[str, SensorMount] = {}
        if self.sensors_path is not None:
            table = _Table(self.sensors_path, self.csv, _SENSORS)
            for chunk in table.chunks():
                names = _sensor_column(table, chunk).tolist()
                x = _check_column(table, chunk, "x", _floats(table, chunk, "x", finite=True)
                                  / self._len_div, MOUNT_M)
                y = _check_column(table, chunk, "y", _floats(table, chunk, "y", finite=True)
                                  / self._len_div, MOUNT_M)
                yaw = _check_column(table, chunk, "yaw", _floats(table, chunk, "yaw", finite=True)
                                    * self._ang_mul, ANGLE_RAD)
                nan = np.full(len(chunk), np.nan)
                fov = (
                    _floats(table, chunk, "fov", finite=False, optional=True) * self._ang_mul
                    if "fov" in chunk.cols
                    else nan
                )
                lo = (
                    _check_column(table, chunk, "min_range", _floats(
                        table, chunk, "min_range", finite=False, optional=True) / self._len_div,
                        LIMIT_M)
                    if "min_range" in chunk.cols
                    else nan
                )
                hi = (
                    _check_column(table, chunk, "max_range", _floats(
                        table, chunk, "max_range", finite=False, optional=True) / self._len_div,
                        LIMIT_M)
                    if "max_range" in chunk.cols
                    else nan
                )
                for i, name in enumerate(names):
                    if name in mounts:
                        raise table.error(int(chunk.lines[i]), f"sensor {name!r} listed twice")
                    mounts[name] = SensorMount(float(x[i]), float(y[i]), float(yaw[i]))
                    self._log_limits[name] = (float(fov[i]), float(lo[i]), float(hi[i]))
        self._mounts = mounts
        return mounts

    def _scan_info(self) -> LogInfo:
        counts: dict[tuple[str, str], int] = {}
        rows = 0
        readings = 0
        t_min: int | None = None
        t_max: int | None = None
        kinds = {RangeBatch: "ranges", PoseBatch: "poses", MountBatch: "sensors"}
        if self.layout == "single":
            counts[(self.ranges_path.name, "ranges")] = 0
            counts[(self.ranges_path.name, "poses")] = 0
        for fname, n_rows, batch in self._stream(ALL_KINDS):
            kind = kinds[type(batch)]
            # Ranges count file rows (a wide row holds a whole ring); poses and mounts count
            # what they are (distinct poses in the single layout).
            n = n_rows if kind == "ranges" else len(batch)
            counts[(fname, kind)] = counts.get((fname, kind), 0) + n
            rows += n_rows
            if isinstance(batch, RangeBatch):
                readings += len(batch)
            if isinstance(batch, (RangeBatch, PoseBatch)) and len(batch):
                lo, hi = int(batch.t_ns.min()), int(batch.t_ns.max())
                t_min = lo if t_min is None else min(t_min, lo)
                t_max = hi if t_max is None else max(t_max, hi)
        role = {"ranges": "range", "poses": "pose", "sensors": "tf_static"}
        topics = [
            TopicInfo(f, f"csv/{k}", c, "csv", role[k])
            for (f, k), c in sorted(counts.items(), key=lambda kv: _ORDER[kv[0][1]])
        ]
        notes = [f"{readings} range readings from {len(self.sensor_names)} sensors"]
        if self.sensor_names:
            notes.append(f"sensors: {', '.join(self.sensor_names)}")
        if self.layout == "single":
            notes.append("poses = the distinct (t, x, y, yaw) rows")
        return LogInfo(
            path=str(self.path),
            format=self.format_name,
            start_ns=t_min,
            end_ns=t_max,
            message_count=rows,
            topics=topics,
            range_topics=[self.ranges_path.name],
            pose_topic=(self.poses_path or self.ranges_path).name,
            notes=notes,
        )


_ORDER = {"ranges": 0, "poses": 1, "sensors": 2}
