"""cli.errors: a SIGTERM ends a command with 143, even one Python drops in a finalizer."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import time
from collections.abc import Iterator

import pytest
import typer

from cli.errors import EXIT_TERMINATED, handle_errors


class _SignalsInFinalizer:
    """Sends SIGTERM to this process from its ``__del__``, where Python drops the handler's
    exception, as in llvmlite's finalizers when numba is interrupted while compiling."""

    def __init__(self, log: list[str]):
        self.log = log

    def __del__(self) -> None:
        self.log.append("finalizer")
        os.kill(os.getpid(), signal.SIGTERM)  # its handler raises in here: dropped
        self.log.append("finalizer finished")


def _busy(seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:  # the rest of the command's work
        pass


def test_sigterm_inside_a_finalizer_still_terminates_the_command(
        capsys: pytest.CaptureFixture[str]) -> None:
    steps: list[str] = []

    @handle_errors
    def command() -> None:
        obj = _SignalsInFinalizer(steps)
        del obj
        _busy(2.0)
        steps.append("the command's work done")

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == EXIT_TERMINATED
    assert steps == ["finalizer"]  # the signal raised again soon after, not lost
    assert capsys.readouterr().err.strip() == "sonarmap: terminated"


def test_a_command_without_a_signal_returns_its_value() -> None:
    assert handle_errors(lambda: 7)() == 7
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler restored


def test_sigterm_inside_a_ctypes_callback_still_terminates_the_command() -> None:
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    compare_t = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
    calls: list[int] = []

    def compare(a: int | None, b: int | None) -> int:  # called by C: exceptions dropped
        calls.append(1)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGTERM)
        return 0

    steps: list[str] = []

    @handle_errors
    def command() -> None:
        values = (ctypes.c_int * 64)(*range(64))
        libc.qsort(values, 64, ctypes.sizeof(ctypes.c_int), compare_t(compare))
        steps.append("sorted")
        _busy(2.0)
        steps.append("the command's work done")

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == EXIT_TERMINATED
    assert steps == ["sorted"] and len(calls) > 1  # the sort went on; the command did not


def test_an_error_after_a_dropped_signal_ends_the_command_as_terminated(
        capsys: pytest.CaptureFixture[str]) -> None:
    @handle_errors
    def command() -> None:
        obj = _SignalsInFinalizer([])
        del obj  # as when llvmlite's callback was cut short and numba then fails:
        raise RuntimeError("no compiled object yet for <Library 'cones_row_spans'>")

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == EXIT_TERMINATED
    assert capsys.readouterr().err.strip() == "sonarmap: terminated"


def test_an_error_without_a_signal_keeps_its_traceback() -> None:
    @handle_errors
    def command() -> None:
        raise RuntimeError("a bug in sonarmap")

    with pytest.raises(RuntimeError, match="a bug in sonarmap"):
        command()


def test_a_signal_deferred_past_the_commands_end_still_ends_it_as_terminated() -> None:
    @handle_errors
    def command() -> str:
        obj = _SignalsInFinalizer([])
        del obj  # the command returns before the deferred signal is delivered again
        return "outputs written"

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == EXIT_TERMINATED
    time.sleep(3 * 0.01)  # the re-delivery, after the default handler is back: ignored


@pytest.fixture
def python_sigint() -> Iterator[None]:
    """SIGINT at Python's own handler, which the command then owns, as in a terminal (a
    shell that starts a job in the background hands it SIGINT ignored, which the command
    leaves alone); the inherited disposition restored after."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, inherited)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, EXIT_TERMINATED),
                                              (signal.SIGINT, 130)])
@pytest.mark.usefixtures("python_sigint")
def test_a_signal_waits_while_numba_compiles_on_the_main_thread(
        signum: int, code: int, capsys: pytest.CaptureFixture[str]) -> None:
    # Inside numba's compiler lock (a kernel compiled or loaded from the cache, nested as a
    # kernel that calls another is), the signal is held; it ends the command as soon as
    # the outermost lock is released, before the next statement.
    from numba.core.compiler_lock import global_compiler_lock

    steps: list[str] = []

    @handle_errors
    def command() -> None:
        with global_compiler_lock:
            with global_compiler_lock:
                os.kill(os.getpid(), signum)
                _busy(0.05)
                steps.append("inner compile finished")
            _busy(0.05)
            steps.append("outer compile finished")
        steps.append("after the compiler")

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == code
    assert steps == ["inner compile finished", "outer compile finished"]
    assert not global_compiler_lock.is_locked()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    assert "sonarmap: " in capsys.readouterr().err


def test_a_signal_outside_numbas_compiler_is_raised_at_once() -> None:
    from numba.core.compiler_lock import global_compiler_lock

    steps: list[str] = []

    @handle_errors
    def command() -> None:
        with global_compiler_lock:
            steps.append("compiled")
        os.kill(os.getpid(), signal.SIGTERM)
        _busy(0.05)
        steps.append("after the signal")

    with pytest.raises(typer.Exit) as exc:
        command()
    assert exc.value.exit_code == EXIT_TERMINATED
    assert steps == ["compiled"]
