"""The suite file of ``sonarmap regress --suite``: which logs, held to which goldens.

```toml
tolerances = "tolerances.toml"        # optional
config = "sonarmap.toml"              # optional default configuration of every log
[[log]]
name = "office"                       # the golden's directory name under --goldens
path = "logs/office.mcap"             # a file, a directory, or a list: one recording
truth = "truth/office.yaml"           # optional ground-truth nav2 map: holds F1 too
truth_trajectory = "truth/office.csv" # optional true trajectory (t,x,y,yaw): F1's recall
                                      #   counts only walls within sensor reach of it
config = "office.toml"                # optional, replaces the default configuration
```

Relative paths are taken relative to the suite file's directory. Every file named must
exist when the suite is read, and names are unique (case-insensitively: a golden is a
directory) plain directory names; any other mistake — an unknown key, a wrong type — is a
:class:`~formats.errors.ConfigError` of one line naming the file and the entry
(``regress.toml: log 'office' (entry 2): unknown key 'pth'``).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from formats.errors import ConfigError
from formats.path_text import path_text_problem, shown
from formats.toml_file import read_toml

__all__ = ["Suite", "SuiteLog", "display_path", "read_suite"]

_TOP_KEYS = frozenset({"tolerances", "config", "log"})
_LOG_KEYS = frozenset({"name", "path", "truth", "truth_trajectory", "config"})
# A golden's directory name: no separators, not hidden (staging siblings are), not . or ..
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+\-]*")
_MAX_NAME = 200  # bytes: the staging sibling of a golden must fit 255


@dataclass(frozen=True)
class SuiteLog:
    """One log of a suite, its paths resolved against the suite file's directory."""

    name: str
    paths: tuple[Path, ...]  # one file or directory, or the files of one recording
    truth: Path | None = None
    truth_trajectory: Path | None = None
    config: Path | None = None  # this log's configuration file (None: the defaults)


@dataclass(frozen=True)
class Suite:
    """A parsed suite file."""

    path: Path
    logs: tuple[SuiteLog, ...]
    tolerances: Path | None = None


def display_path(p: Path) -> str:
    """``p`` as goldens record it: relative to the working directory when inside it
    (normalised, so ``a/../b`` reads ``b``), absolute otherwise."""
    absolute = Path(os.path.abspath(p))
    try:
        return absolute.relative_to(Path.cwd()).as_posix() or "."
    except ValueError:
        return str(absolute)


def _fail(suite: Path, where: str, reason: str) -> ConfigError:
    return ConfigError(f"{where}: {reason}" if where else reason, suite)


def _string(value: Any, key: str, suite: Path, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise _fail(suite, where, f"'{key}' must be a non-empty string, got {value!r}")
    return value


def _file(value: Any, key: str, suite: Path, where: str, *, directory_ok: bool) -> Path:
    text = _string(value, key, suite, where)
    problem = path_text_problem(text)
    if problem is not None:
        raise _fail(suite, where, f"{key} {shown(text)} {problem}")
    p = Path(text).expanduser()
    p = p if p.is_absolute() else suite.parent / p
    if not p.exists():
        raise _fail(suite, where, f"{key} {text!r} not found ({p})")
    if not directory_ok and p.is_dir():
        raise _fail(suite, where, f"{key} {text!r} is a directory, not a file")
    return Path(os.path.normpath(p))


def _log(entry: Any, number: int, suite: Path, default_config: Path | None) -> SuiteLog:
    where = f"[[log]] entry {number}"
    if not isinstance(entry, dict):
        raise _fail(suite, where, f"must be a table, got {type(entry).__name__}")
    if "name" in entry:
        name = _string(entry["name"], "name", suite, where)
        where = f"log {name!r} (entry {number})"
        if not _NAME.fullmatch(name) or len(os.fsencode(name)) > _MAX_NAME:
            raise _fail(suite, where, "'name' must be a plain directory name (letters, "
                        "digits, '_', '-', '.', '+'; not starting with '.' or '-')")
    unknown = sorted(set(entry) - _LOG_KEYS)
    if unknown:
        raise _fail(suite, where, f"unknown key '{unknown[0]}' (known: "
                    f"{', '.join(sorted(_LOG_KEYS))})")
    for key in ("name", "path"):
        if key not in entry:
            raise _fail(suite, where, f"missing key '{key}'")
    raw = entry["path"]
    items = raw if isinstance(raw, list) else [raw]
    if not items:
        raise _fail(suite, where, "'path' is an empty list")
    paths = tuple(_file(p, "path", suite, where, directory_ok=True) for p in items)
    if len(set(paths)) != len(paths):
        raise _fail(suite, where, "'path' names the same file twice")

    def optional(key: str) -> Path | None:
        if key not in entry:
            return None
        return _file(entry[key], key, suite, where, directory_ok=False)

    truth, trajectory = optional("truth"), optional("truth_trajectory")
    if trajectory is not None and truth is None:
        raise _fail(suite, where, "'truth_trajectory' needs 'truth' (it scopes F1's recall)")
    config = optional("config") or default_config
    return SuiteLog(entry["name"], paths, truth, trajectory, config)


def read_suite(path: str | Path) -> Suite:
    """Parse and check a suite file; ConfigError (one line: file, entry, what) if wrong."""
    suite = Path(path)
    data = read_toml(suite, "suite")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise _fail(suite, "", f"unknown key '{unknown[0]}' (known: "
                    f"{', '.join(sorted(_TOP_KEYS))})")
    tolerances = (_file(data["tolerances"], "tolerances", suite, "", directory_ok=False)
                  if "tolerances" in data else None)
    config = (_file(data["config"], "config", suite, "", directory_ok=False)
              if "config" in data else None)
    entries = data.get("log")
    if not isinstance(entries, list) or not entries:
        raise _fail(suite, "", "no logs: add a [[log]] table with 'name' and 'path'")
    logs: list[SuiteLog] = []
    seen: dict[str, int] = {}
    for number, entry in enumerate(entries, start=1):
        log = _log(entry, number, suite, config)
        first = seen.setdefault(log.name.casefold(), number)
        if first != number:
            raise _fail(suite, f"log {log.name!r} (entry {number})",
                        f"duplicate name (entry {first} has it already)")
        logs.append(log)
    return Suite(suite, tuple(logs), tolerances)
