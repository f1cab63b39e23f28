"""The one place where exceptions become exit codes.

Exit codes: 0 success, 1 bad input / configuration / refused output (a one-line message on
stderr, no traceback), 2 usage errors (typer/click). Any other exception is a bug in
sonarmap and keeps its traceback.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import ParamSpec, TypeVar

import typer

from formats.errors import SonarmapError

P = ParamSpec("P")
R = TypeVar("R")

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same cleanup runs (temporary outputs)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside, SIGTERM unwinds the command like SIGINT (``with`` blocks clean up:
    no ``.OUT.tmp-*`` is left behind). Only the main thread can install handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _quiet_finalizers() -> None:
    """After a signal, the one line said is the whole message: an interrupted native
    library (numba compiling: llvmlite's ``ObjectRef.__del__``) may fail in its finalizers
    at exit, which Python would print as "Exception ignored in …". Silenced at exit only
    (``atexit`` runs before those finalizers), so an in-process caller keeps its hook."""
    atexit.register(setattr, sys, "unraisablehook", lambda unraisable: None)


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
