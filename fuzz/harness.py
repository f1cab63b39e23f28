"""The reader property, checked one mutated input at a time.

Property: opening a log with :func:`formats.open_log` and draining ``info()`` and
``batches()`` either succeeds (possibly with fewer records and the loss in the notes) or
raises :class:`~formats.errors.FormatError` / :class:`~formats.errors.TopicError` with a
one-line message naming the file — never another exception, never longer than a CPU-time
limit, never memory proportional to a declared size rather than the file size.

:func:`build_targets` writes the valid fixtures (a short simulated run in every format
plus the real fixtures of ``tests/data``); :func:`check` runs one mutated input.
"""

from __future__ import annotations

import io
import shutil
import signal
import tarfile
import traceback
import tracemalloc
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from fuzz.mutators import Mutation, apply, structure_points

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
TIME_LIMIT_S = 5.0
MEMORY_BASE_BYTES = 64 << 20  # allowed peak Python/numpy allocation besides 10 x file size


@dataclass(frozen=True)
class Target:
    """A valid log and the one file inside it that gets mutated.

    ``log`` is what is opened (a file, or a bag/CSV directory); ``member`` the mutated
    file relative to the log's directory ('' = the log file itself); ``walker`` the
    structure walker of that file ('ros1', 'mcap', 'sqlite' or ''); ``text`` selects the
    CSV row mutations. ``companions``: intact files opened with it as one recording in
    several files (a damaged split beside an intact copy of the same recording).
    """

    name: str
    family: str  # ros1, ros2, mcap, csv: how counts are reported
    log: Path
    member: str = ""
    walker: str = ""
    text: bool = False
    companions: tuple[Path, ...] = ()

    @property
    def file(self) -> Path:
        return self.log / self.member if self.member else self.log

    def valid_bytes(self) -> bytes:
        return self.file.read_bytes()

    def points(self) -> list[tuple[int, int]]:
        return structure_points(self.valid_bytes(), self.walker) if self.walker else []

    def materialize(self, work: Path, data: bytes) -> Path:
        """A copy of the log under ``work`` with the member file replaced by ``data``."""
        work.mkdir(parents=True, exist_ok=True)
        dst = work / self.log.name
        if dst.exists():
            shutil.rmtree(dst) if dst.is_dir() else dst.unlink()
        if self.member:
            shutil.copytree(self.log, dst)
            (dst / self.member).write_bytes(data)
        else:
            dst.write_bytes(data)
        return dst


@dataclass
class Outcome:
    """What one input did: ``status`` is 'ok', 'loss' (read, with losses recorded),
    'rejected' (a proper FormatError/TopicError, one line naming the file) or 'defect';
    ``detail`` the error line or the defect (with the traceback's last frame)."""

    status: str
    detail: str = ""
    records: int = 0
    peak_bytes: int = 0

    @property
    def defect(self) -> bool:
        return self.status == "defect"


class _Timeout(BaseException):
    """Raised by the watchdog alarm (a BaseException, so `except Exception` can't eat it)."""


@contextmanager
def _time_limit(seconds: float) -> Iterator[None]:
    """Raise _Timeout once the process has spent ``seconds`` of CPU time (user + system)
    inside the block. CPU time, not wall time: a loaded machine (other jobs on the same
    cores) slows the clock on the wall but not the work a reader does, so the limit means
    the same on a fast laptop and on a busy CI runner."""

    def on_alarm(signum: int, frame: object) -> None:
        raise _Timeout

    old = signal.signal(signal.SIGPROF, on_alarm)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, old)


def read_everything(path: Path | list[Path]) -> int:
    """Open a log (or the files of one recording), read ``info()`` and drain
    ``batches()``; returns the records read (:func:`read_with_losses`)."""
    return read_with_losses(path)[0]


def read_with_losses(path: Path | list[Path]) -> tuple[int, int]:
    """Open a log (or the files of one recording), read ``info()`` and drain
    ``batches()``; returns the records read and the losses recorded.

    A log without a range or pose topic (TopicError from ``batches``) still has its
    container drained message by message (ROS logs), so the container parser is
    exercised on every fixture.
    """
    from formats import open_log
    from formats.errors import TopicError

    records = 0
    with open_log(path) as reader:
        info = reader.info()
        records += len(info.topics)
        try:
            for batch in reader.batches():
                records += len(batch)
        except TopicError:
            source = getattr(reader, "source", None)
            if source is None:
                raise
            for raw in source.raw_batches([c.id for c in source.connections]):
                records += len(raw)
        losses = len(reader.info().losses)
    return records, losses


def check(target: Target, data: bytes, work: Path, time_limit_s: float = TIME_LIMIT_S) -> Outcome:
    """Write ``data`` as the target's member under ``work`` and check the property."""
    from formats.errors import FormatError, TopicError

    path = target.materialize(work, data)
    names = {path.name, target.file.name}
    logs = [path, *target.companions]
    size = sum(p.stat().st_size for log in logs
               for p in ([log] if log.is_file() else log.rglob("*")))
    limit = MEMORY_BASE_BYTES + 10 * size
    tracemalloc.start()
    try:
        with _time_limit(time_limit_s):
            records, losses = read_with_losses(logs if target.companions else path)
        outcome = Outcome("loss" if losses else "ok", records=records)
    except _Timeout:
        outcome = Outcome("defect", f"timeout: more than {time_limit_s} s of CPU time")
    except (FormatError, TopicError) as err:
        text = str(err)
        if "\n" in text:
            outcome = Outcome("defect", f"multi-line message: {text!r}")
        elif not any(n in text for n in names):
            outcome = Outcome("defect", f"message does not name the file: {text!r}")
        else:
            outcome = Outcome("rejected", text)
    except BaseException as err:  # the property: nothing else may escape
        if isinstance(err, KeyboardInterrupt):
            raise
        frame = traceback.extract_tb(err.__traceback__)[-1]
        where = f"{Path(frame.filename).name}:{frame.lineno}"
        outcome = Outcome("defect", f"{type(err).__name__} at {where}: {str(err)[:200]}")
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    outcome.peak_bytes = peak
    if peak > limit and not outcome.defect:
        outcome = Outcome(
            "defect", f"memory: peak {peak >> 20} MiB > limit {limit >> 20} MiB", peak_bytes=peak
        )
    return outcome


def check_mutation(target: Target, m: Mutation, work: Path) -> Outcome:
    """:func:`check` of ``target`` changed by mutation ``m``."""
    return check(target, apply(target.valid_bytes(), m), work)


# --------------------------------------------------------------------------- fixtures


def _simulated_content() -> object:
    """A short simulated run (a 4 x 3 m room, two sonar revolutions per second)."""
    import numpy as np

    from pipeline.tools.simulate.simulate import SimOptions, simulate
    from pipeline.tools.simulate.world import world_from_dict

    world = world_from_dict(
        {"segment": [{"from": [0, 0], "to": [4, 0]}, {"from": [4, 0], "to": [4, 3]},
                     {"from": [4, 3], "to": [0, 3]}, {"from": [0, 3], "to": [0, 0]}],
         "circle": [{"center": [2, 1.5], "radius": 0.2}]}
    )
    sim = simulate(world, np.array([[1.0, 1.0], [3.0, 1.0], [3.0, 2.0]]),
                   SimOptions(seed=3, ring_rate_hz=2, sonar_model="ideal"))
    return sim.to_content()


# (target name, writer format, path name, compression)
SIMULATED = (
    ("ros1-none", "ros1", "sim.bag", "none"),
    ("ros1-bz2", "ros1", "sim_bz2.bag", "bz2"),
    ("ros1-lz4", "ros1", "sim_lz4.bag", "lz4"),
    ("ros2-db3", "ros2", "sim_db3", "none"),
    ("ros2-mcap", "ros2-mcap", "sim_r2mcap", "none"),
    ("mcap-zstd", "mcap", "sim_zstd.mcap", "zstd"),
    ("mcap-lz4", "mcap", "sim_lz4.mcap", "lz4"),
    ("mcap-ros1-none", "mcap-ros1", "sim_ros1.mcap", "none"),
    ("csv-single", "csv", "sim.csv", "none"),
    ("csv-set", "csv-set", "sim_csv", "none"),
)

ROS2_REAL = (
    ("ros2-real-talker-db3", "rosbag2_py/test/resources/sqlite3/talker", "talker.db3", "sqlite"),
    ("ros2-real-talker-mcap", "rosbag2_py/test/resources/mcap/talker", "talker.mcap", "mcap"),
    ("ros2-real-cdr-mcap", "rosbag2_tests/resources/mcap/cdr_test", "cdr_test_0.mcap", "mcap"),
)


def build_targets(root: Path) -> list[Target]:
    """Write the fixtures under ``root`` (created) and return every target."""
    import zstandard

    from formats.log_writers import write_log

    root.mkdir(parents=True, exist_ok=True)
    content = _simulated_content()
    out: list[Target] = []
    for name, fmt, fname, comp in SIMULATED:
        p = root / fname
        if not p.exists():
            write_log(content, p, fmt, compression=comp)  # type: ignore[arg-type]
        if fmt == "ros1":
            out.append(Target(name, "ros1", p, walker="ros1"))
        elif fmt in ("ros2", "ros2-mcap"):
            storage = next(q.name for q in p.iterdir() if q.suffix in (".db3", ".mcap"))
            walker = "sqlite" if storage.endswith(".db3") else "mcap"
            out.append(Target(name, "ros2", p, storage, walker))
            out.append(Target(f"{name}-metadata", "ros2", p, "metadata.yaml", text=False))
        elif fmt.startswith("mcap"):
            out.append(Target(name, "mcap", p, walker="mcap"))
        elif fmt == "csv":
            out.append(Target(name, "csv", p, text=True))
        else:
            for member in ("ranges.csv", "poses.csv", "sensors.csv"):
                out.append(Target(f"{name}-{member}", "csv", p, member, text=True))
    for bag in ("tiago-sonar.bag", "example-unsorted-chunks.bag", "example-bz2.bag"):
        out.append(Target(f"ros1-real-{bag}", "ros1", DATA / "ros1" / bag, walker="ros1"))
    real = root / "ros2-real"
    if not real.exists():
        archive = DATA / "ros2" / "ros2-fixtures.tar.zst"
        raw = zstandard.ZstdDecompressor().stream_reader(archive.open("rb")).read()
        with tarfile.open(fileobj=io.BytesIO(raw)) as tar:
            tar.extractall(real, filter="data")
    for name, rel, member, walker in ROS2_REAL:
        out.append(Target(name, "ros2", real / rel, member, walker))
    # A standalone copy of a real rosbag2 MCAP: read as an MCAP file (no metadata.yaml).
    standalone = root / "real-cdr.mcap"
    if not standalone.exists():
        shutil.copyfile(real / ROS2_REAL[2][1] / ROS2_REAL[2][2], standalone)
    out.append(Target("mcap-real-cdr", "mcap", standalone, walker="mcap"))
    # One recording in two files, the damaged one beside an intact copy (read as one:
    # formats/ros/multi_source.py merges them by time and reads identical messages once).
    by_name = {t.name: t for t in out}
    for name in ("ros1-lz4", "mcap-zstd", "ros2-db3"):
        t = by_name[name]
        copy = root / "copies" / t.log.name
        if not copy.exists():
            copy.parent.mkdir(exist_ok=True)
            (shutil.copytree if t.log.is_dir() else shutil.copyfile)(t.log, copy)
        out.append(Target(f"{name}-beside-a-copy", t.family, t.log, t.member, t.walker,
                          companions=(copy,)))
    return out
