"""The one place where exceptions become exit codes.

Exit codes: 0 success, 1 bad input / configuration / refused output (a one-line message on
stderr, no traceback), 2 usage errors (typer/click). Any other exception is a bug in
sonarmap and keeps its traceback.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import typer

from formats.errors import SonarmapError

P = ParamSpec("P")
R = TypeVar("R")

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


def fail(message: str) -> typer.Exit:
    """Print ``sonarmap: error: <message>`` (one line) to stderr; return the Exit to raise."""
    print(f"sonarmap: error: {' '.join(message.split())}", file=sys.stderr)
    return typer.Exit(EXIT_FAILURE)


def handle_errors(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorate a command: SonarmapError → one line on stderr and exit 1."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return fn(*args, **kwargs)
        except SonarmapError as err:
            raise fail(str(err)) from None
        except KeyboardInterrupt:
            print("sonarmap: interrupted", file=sys.stderr)
            raise typer.Exit(130) from None

    return wrapper
