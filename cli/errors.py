"""The one place where exceptions become exit codes.

Exit codes: 0 success, 1 bad input / configuration / refused output (a one-line message on
stderr, no traceback), 2 usage errors (typer/click). Any other exception is a bug in
sonarmap and keeps its traceback.
"""

from __future__ import annotations

import _thread
import atexit
import contextlib
import functools
import gc
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, ParamSpec, TypeVar

import typer

from formats.errors import SonarmapError

if TYPE_CHECKING:
    from sys import UnraisableHookArgs

    from formats.storage.location import Location

P = ParamSpec("P")
R = TypeVar("R")

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same cleanup runs (temporary outputs)."""


_REDELIVER_S = 0.01  # a signal Python dropped is delivered again after this
_terminated: set[int] = set()  # holds SIGTERM once one arrived during the current command
_closing: list[bool] = []  # non-empty while the handlers are being restored


def _unwind(signum: int, frame: object) -> None:
    """The handler of SIGTERM (raises :class:`Terminated`) and SIGINT (KeyboardInterrupt),
    held while numba compiles on this thread (:class:`_AfterCompiler`)."""
    if signum == signal.SIGTERM:
        _terminated.add(signum)
    if _closing:  # the command is over: its ending is already the signal's
        return
    if _holds_numba_compiler():
        _after_compiler.defer(signum)
        return
    raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt


def _holds_numba_compiler() -> bool:
    """Whether this thread is inside numba's compiler (compiling a kernel or loading it from
    numba's cache). An exception raised there lands in llvmlite's ctypes callbacks, where
    Python drops it, and can leave the kernel half loaded (measured: 4 segfaults in 450 runs
    killed 0.2-3 s after start, at a half-loaded kernel's first call or disposing of a
    half-compiled module at exit; none since the signal waits)."""
    lock = sys.modules.get("numba.core.compiler_lock")
    return lock is not None and bool(lock.global_compiler_lock.is_locked())


class _AfterCompiler:
    """Signals that arrived while the main thread was inside numba's compiler, delivered
    again (``signal.raise_signal``) when it leaves it: numba announces each release of its
    compiler lock (the ``numba:compiler_lock`` event)."""

    def __init__(self) -> None:
        self.pending: list[int] = []
        self._listener: object | None = None

    def defer(self, signum: int) -> None:
        if signum not in self.pending:
            self.pending.append(signum)
        if self._listener is None:
            from numba.core import event

            after = self

            class Released(event.Listener):
                def on_start(self, ev: object) -> None:
                    pass

                def on_end(self, ev: object) -> None:
                    after.released()

            self._listener = Released()
            event.register("numba:compiler_lock", self._listener)  # type: ignore[no-untyped-call]

    def released(self) -> None:
        """Numba released its compiler lock: deliver the pending signals if the main thread
        holds it no more."""
        if (threading.current_thread() is threading.main_thread() and self.pending
                and not _holds_numba_compiler()):
            pending, self.pending = self.pending, []
            for signum in pending:
                signal.raise_signal(signum)

    def close(self) -> None:
        """Forget pending signals and stop listening (the command is over)."""
        self.pending = []
        if self._listener is not None:
            from numba.core import event

            event.unregister("numba:compiler_lock", self._listener)  # type: ignore[no-untyped-call]
            self._listener = None


_after_compiler = _AfterCompiler()


def _redeliver_dropped(previous: Callable[[UnraisableHookArgs], object]
                       ) -> Callable[[UnraisableHookArgs], None]:
    """An ``unraisablehook`` that delivers again a signal whose exception Python dropped:
    one raised inside a ``__del__`` or a ctypes callback (llvmlite's, while numba
    compiles) is printed as "Exception ignored …" and the command would go on. Other
    unraisable exceptions go to ``previous``, unless a signal arrived before them."""

    def hook(unraisable: UnraisableHookArgs) -> None:
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            if not _terminated:  # after a signal, a finalizer's failure is the signal's
                previous(unraisable)
            return
        signum = signal.SIGTERM if isinstance(unraisable.exc_value, Terminated) else signal.SIGINT
        # From another thread: delivered now, the signal would land in the same finalizer.
        timer = threading.Timer(_REDELIVER_S, _thread.interrupt_main, (signum,))
        timer.daemon = True
        timer.start()

    return hook


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside, SIGTERM unwinds the command like SIGINT (``with`` blocks clean up:
    no ``.OUT.tmp-*`` is left behind). Either signal waits while numba compiles or loads
    a kernel on the main thread (:class:`_AfterCompiler`); a signal Python dropped in a
    finalizer or a callback is delivered again; once one arrived, the command ends as
    terminated however it ends (an error after it is the interruption's). Only the main
    thread can install handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _terminated.clear()
    previous = signal.signal(signal.SIGTERM, _unwind)
    previous_int = signal.getsignal(signal.SIGINT)
    own_sigint = previous_int is signal.default_int_handler  # a caller's own handler stays
    if own_sigint:
        signal.signal(signal.SIGINT, _unwind)
    previous_hook, sys.unraisablehook = sys.unraisablehook, _redeliver_dropped(sys.unraisablehook)
    try:
        yield
    except Exception as err:  # a library left broken by the signal it dropped, say
        if _terminated:
            raise Terminated from err
        raise
    else:
        if _terminated:
            raise Terminated
    finally:
        # A signal delivered again now (a finalizer's, by the timer) must not cut this short.
        _closing.append(True)
        signal.signal(signal.SIGTERM, previous)
        if own_sigint:
            signal.signal(signal.SIGINT, previous_int)
        _after_compiler.close()
        if _terminated:  # the interrupted library's garbage, while the hook is this one
            gc.collect()
        sys.unraisablehook = previous_hook
        _closing.clear()


def _quiet_finalizers() -> None:
    """After a signal, the one line said is the whole message: an interrupted native
    library (numba compiling: llvmlite's ``ObjectRef.__del__``) may fail in its finalizers
    at exit, which Python would print as "Exception ignored in …". Silenced at exit only
    (``atexit`` runs before those finalizers), so an in-process caller keeps its hook."""
    atexit.register(setattr, sys, "unraisablehook", lambda unraisable: None)


def check_path_arguments(values: Iterable[object]) -> None:
    """Refuse, before a command starts, a path argument the OS cannot take: a component
    longer than NAME_MAX bytes (a one-line OutputError instead of an OSError traceback
    from the first ``exists()``)."""
    from pathlib import Path

    from formats.writers.atomic import check_path_names

    for v in values:
        for p in (v if isinstance(v, list | tuple) else [v]):
            if isinstance(p, Path):
                check_path_names(p)


def location_argument(text: str) -> Location:
    """A command-line name of a log or an output as a location (a URL stays a URL, never a
    path with its ``//`` folded); a local path is refused like any path argument when a
    component is too long (:func:`check_path_arguments`)."""
    from formats.storage.location import as_location

    where = as_location(text)
    check_path_arguments([where])
    return where


def fail(message: str) -> typer.Exit:
    """Print ``sonarmap: error: <message>`` (one line) to stderr; return the Exit to raise."""
    print(f"sonarmap: error: {' '.join(message.split())}", file=sys.stderr)
    return typer.Exit(EXIT_FAILURE)


def handle_errors(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorate a command: SonarmapError → one line on stderr and exit 1; Ctrl-C → 130,
    SIGTERM → 143, both after the ``with`` blocks cleaned up."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            check_path_arguments(kwargs.values())
            with sigterm_as_interrupt():
                return fn(*args, **kwargs)
        except SonarmapError as err:
            raise fail(str(err)) from None
        except Terminated:
            print("sonarmap: terminated", file=sys.stderr)
            _quiet_finalizers()
            raise typer.Exit(EXIT_TERMINATED) from None
        except KeyboardInterrupt:
            print("sonarmap: interrupted", file=sys.stderr)
            _quiet_finalizers()
            raise typer.Exit(EXIT_INTERRUPTED) from None

    return wrapper
