"""Help that reads as words: ``run LOG -o OUT --range-topic TOPIC``, not ``{log}``,
``<path>`` or ``<list[str]>``.

Every command is built with :class:`WordsCommand`, which gives each parameter that has no
metavar of its own a word: from :data:`METAVARS` by parameter name, else the name in
capitals. One place, so commands added later read the same.
"""

from __future__ import annotations

from typing import Any

import click
import typer
from typer.core import TyperArgument, TyperCommand

__all__ = ["METAVARS", "WordsArgument", "WordsCommand", "use_words"]

#: Parameter name → the word shown for its value.
METAVARS = {
    "log": "LOG",
    "logs": "LOG...",
    "inputs": "INPUT...",
    "output": "OUT",
    "config": "FILE",
    "format": "FORMAT",
    "range_topic": "TOPIC",
    "pose_topic": "TOPIC",
    "laser_topic": "TOPIC",
    "method": "METHOD",
    "resolution": "METRES",
    "run_dir": "RUN",
    "truth": "MAP.yaml",
    "trajectory": "CSV",
    "golden": "DIR",
    "tolerances": "FILE",
    "manifest": "FILE",
    "world": "WORLD",
    "waypoints": "CSV",
    "scheduler": "ADDRESS",
    "tolerance": "METRES",
    "reach": "METRES",
}


class WordsArgument(TyperArgument):
    """An argument shown as its word alone: ``LOG`` (``[INPUT...]`` when optional), not
    ``{log}`` and ``log <path>``."""

    def _usage_display_name(self) -> str:
        name = self.display_name_raw
        return name if self.required else f"[{name}]"

    def _rich_display_name(self) -> str:
        return self.display_name_raw

    def display_type_rich(self, ctx: click.Context) -> str | None:  # type: ignore[override]
        return None


class WordsCommand(TyperCommand):
    """A typer command whose parameters show words as metavars (see the module)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            if isinstance(param, TyperArgument):
                param.__class__ = WordsArgument
            if param.metavar is not None:
                continue
            if isinstance(param, click.Option) and (param.is_flag or param.count):
                continue
            name = param.name or ""
            word = METAVARS.get(name, name.upper())
            if isinstance(param, click.Argument) and param.nargs != 1 and not word.endswith("..."):
                word += "..."
            param.metavar = word


def use_words(app: typer.Typer) -> None:
    """Build every command registered on ``app`` (so far) with :class:`WordsCommand`."""
    for info in app.registered_commands:
        if info.cls is None or info.cls is TyperCommand:  # typer's default: replace it
            info.cls = WordsCommand
