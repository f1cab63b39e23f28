"""The driver of ``sonarmap regress --suite``: every log on the batch's Dask workers.

Before anything runs, each log is planned: its configuration loaded, its golden looked
at. A log that cannot run (a bad configuration; comparing: no golden — ``no golden for
office: run with --update``; updating: a directory under ``--goldens`` that is not a
golden sonarmap wrote, or one that is or holds an input of the suite) gets its failed
row at once; the others go to the workers (:func:`.check.check_log`), largest input
first, each mapping into
a temporary work directory removed at the end. Updating, the driver puts each staged
golden in place as it arrives (:func:`.golden_dir.replace_golden`; byte-identical goldens
are left untouched), so an interrupted update leaves every golden old or new.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

from formats.errors import InputError, SonarmapError
from formats.writers.atomic import make_dir
from pipeline.config import load_config
from pipeline.cores import usable_cores
from pipeline.tools.batch import MEMORY_LIMIT
from pipeline.tools.regress import Tolerances, load_tolerances
from pipeline.tools.suite.check import CheckJob, CheckResult, check_log
from pipeline.tools.suite.golden_dir import (
    alive,
    golden_refusal,
    recover_goldens,
    replace_golden,
    same_golden,
)
from pipeline.tools.suite.suite_file import Suite, SuiteLog, display_path

__all__ = ["HOLDS", "SuiteResult", "plan_log", "run_suite"]

#: Statuses of a log that holds (the suite exits 0 only when every log has one).
HOLDS = frozenset({"ok", "new", "updated", "unchanged"})

SuiteProgress = Callable[[int, int], None]  # (logs finished, logs total)


@dataclass
class SuiteResult:
    """What a suite did: one outcome per log, in the suite file's order."""

    suite: Path
    goldens: Path
    update: bool
    outcomes: list[CheckResult]
    tolerances: Tolerances

    @property
    def ok(self) -> bool:
        return all(o.status in HOLDS for o in self.outcomes)

    def count(self, *statuses: str) -> int:
        return sum(o.status in statuses for o in self.outcomes)


def _inputs(log: SuiteLog, suite: Suite) -> list[Path]:
    named = [*log.paths, log.truth, log.truth_trajectory, log.config, suite.path,
             suite.tolerances]
    return [Path(os.path.abspath(p)) for p in named if p is not None]


def _input_clash(final: Path, suite: Suite) -> Path | None:
    """An input of the suite that ``final`` is, holds, or lies inside (a log directory)."""
    f = Path(os.path.abspath(final))
    for log in suite.logs:
        for p in _inputs(log, suite):
            if f == p or p.is_relative_to(f) or (p.is_dir() and f.is_relative_to(p)):
                return p
    return None


def plan_log(log: SuiteLog, suite: Suite, goldens: Path, update: bool,
          tol: Tolerances, work: Path, diff_dir: Path | None) -> CheckJob | CheckResult:
    """The job of one log, or its failed row when it cannot run."""
    golden = goldens / log.name
    try:
        cfg = load_config(log.config)
    except SonarmapError as err:
        return CheckResult(log.name, "error", str(err), error_type=type(err).__name__)
    if update:
        clash = _input_clash(golden, suite)
        if clash is not None:
            return CheckResult(log.name, "error", f"{golden}: is or holds an input of the "
                               f"suite ({clash}); not writing it", error_type="OutputError")
        reason = golden_refusal(golden)
        if reason is not None:
            return CheckResult(log.name, "error", f"{golden}: {reason}; not replacing it",
                               error_type="OutputError")
    elif not golden.is_dir():
        return CheckResult(log.name, "error",
                           f"no golden for {log.name}: run with --update ({golden} not found)",
                           error_type="InputError")
    diff = None
    if diff_dir is not None and not update:
        diff = str(diff_dir / f"{log.name}.png")
    return CheckJob(
        name=log.name,
        paths=tuple(display_path(p) for p in log.paths),
        config=cfg.to_dict(),
        golden_dir=display_path(golden),
        work_dir=str(work),
        tolerances=asdict(tol),
        update=update,
        truth=None if log.truth is None else display_path(log.truth),
        truth_trajectory=None if log.truth_trajectory is None
        else display_path(log.truth_trajectory),
        diff_png=diff,
        cwd=os.getcwd(),
    )


def _put_in_place(result: CheckResult, goldens: Path) -> CheckResult:
    """An update's staged golden moved under ``goldens`` (the driver's side)."""
    if result.status == "error" or result.staged is None:
        return result
    final, staged = goldens / result.name, Path(result.staged)
    try:
        if same_golden(staged, final):
            result.status = "unchanged"
        else:
            replace_golden(staged, final)
    except SonarmapError as err:
        result.status, result.reason, result.error_type = "error", str(err), type(err).__name__
    return result


_WORK = re.compile(r"sonarmap-regress-(?P<pid>\d+)-.+")


@contextlib.contextmanager
def _work_dir() -> Iterator[Path]:
    """A temporary directory for the runs, removed at the end; the ones that suites killed
    before their end left (their process is gone) are removed first."""
    tmp = Path(tempfile.gettempdir())
    with contextlib.suppress(OSError):
        for d in tmp.iterdir():
            m = _WORK.fullmatch(d.name)
            if m and d.is_dir() and not d.is_symlink() and not alive(int(m["pid"])):
                shutil.rmtree(d, ignore_errors=True)
    work = Path(tempfile.mkdtemp(prefix=f"sonarmap-regress-{os.getpid()}-"))
    try:
        yield work
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_suite(
    suite: Suite,
    goldens: Path,
    *,
    workers: int | None = None,
    memory_limit: str | int = MEMORY_LIMIT,
    update: bool = False,
    diff_dir: Path | None = None,
    tolerances: Path | None = None,
    progress: SuiteProgress | None = None,
) -> SuiteResult:
    """Run every log of ``suite`` against (or, ``update``, into) ``goldens/<name>``.

    Raises SonarmapError only for the whole suite (tolerances, a missing goldens directory
    when comparing, an unwritable diff or goldens directory); a log's failure is its row.
    """
    from distributed import as_completed

    from pipeline.tools.batch import _client  # the batch's local cluster, warmed workers

    tol = load_tolerances(tolerances or suite.tolerances)
    goldens = Path(goldens)
    if update:
        make_dir(goldens, "goldens directory")
        recover_goldens(goldens)
    elif not goldens.is_dir():
        raise InputError("goldens directory not found (make it with --update)", goldens)
    if diff_dir is not None and not update:
        make_dir(diff_dir, "diff directory")
        for log in suite.logs:  # a picture of an earlier run must not outlive its change
            (diff_dir / f"{log.name}.png").unlink(missing_ok=True)
    done: dict[str, CheckResult] = {}
    total = len(suite.logs)
    with _work_dir() as work:
        plans = {log.name: plan_log(log, suite, goldens, update, tol, work, diff_dir)
                 for log in suite.logs}
        jobs = [p for p in plans.values() if isinstance(p, CheckJob)]
        done |= {n: p for n, p in plans.items() if isinstance(p, CheckResult)}
        if progress is not None:
            progress(len(done), total)
        if jobs:
            n = min(workers or usable_cores(), len(jobs))
            with _client(n, None, memory_limit) as client:
                futures = {client.submit(check_log, job, pure=False,
                                         priority=_input_bytes(job),
                                         key=f"sonarmap-regress-{job.name}-"
                                             f"{secrets.token_hex(4)}"): job.name
                           for job in jobs}
                try:
                    for fut in as_completed(futures, loop=client.loop):
                        name = futures[fut]
                        done[name] = _put_in_place(_collect(fut, name), goldens)
                        if progress is not None:
                            progress(len(done), total)
                except BaseException:
                    client.cancel(list(futures))
                    raise
    outcomes = [done[log.name] for log in suite.logs]
    return SuiteResult(suite.path, goldens, update, outcomes, tol)


def _input_bytes(job: CheckJob) -> int:
    """The size of a log's input, bytes: the workers take the largest logs first, so that
    a long log does not start last and leave the other workers idle at the end."""
    total = 0
    for text in job.paths:
        p = Path(text)
        files = p.rglob("*") if p.is_dir() else [p]
        total += sum(f.stat().st_size for f in files if f.is_file())
    return total


def _collect(fut: object, name: str) -> CheckResult:
    """A finished task's result; a task that died (its worker killed) is an error row."""
    try:
        result = fut.result()  # type: ignore[attr-defined]
    except Exception as err:
        return CheckResult(name, "error", " ".join(f"{type(err).__name__}: {err}".split()),
                           error_type=type(err).__name__)
    assert isinstance(result, CheckResult)
    return result
