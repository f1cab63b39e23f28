"""Golden directories: the marker, what --update may replace, and atomic replacement that
a kill at any moment leaves old or new."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from formats.errors import OutputError
from pipeline.tools.suite.golden_dir import (
    GOLDEN_MARKER,
    golden_refusal,
    recover_goldens,
    replace_golden,
    same_golden,
)


def staged(d: Path, tag: str, size: int = 1000) -> Path:
    """A golden-like directory whose every file says ``tag`` (``size`` bytes each)."""
    d.mkdir(parents=True)
    files = ["config.toml", "map.pgm", "map.yaml", "metrics.json"]
    for name in files:
        (d / name).write_text((tag * size)[:size], encoding="utf-8")
    (d / GOLDEN_MARKER).write_text(json.dumps({"written_by": "sonarmap regress --update", "files": files}) + "\n",
                                   encoding="utf-8")
    return d


def contents(d: Path) -> dict[str, str]:
    return {p.name: p.read_text(encoding="utf-8") for p in sorted(d.iterdir())}


def test_replace_writes_new_then_replaces_only_goldens(tmp_path: Path) -> None:
    goldens = tmp_path / "goldens"
    a, b = staged(tmp_path / "a", "A"), staged(tmp_path / "b", "B")
    replace_golden(a, goldens / "office")
    assert contents(goldens / "office") == contents(a)
    assert same_golden(a, goldens / "office") and not same_golden(b, goldens / "office")
    replace_golden(b, goldens / "office")
    assert contents(goldens / "office") == contents(b)
    assert sorted(p.name for p in goldens.iterdir()) == ["office"]  # no staging left


@pytest.mark.parametrize(("make", "reason"), [
    (lambda d: (d.mkdir(), (d / "notes.txt").write_text("mine")), "has no .sonarmap-golden"),
    (lambda d: (staged(d, "A"), (d / "extra.txt").write_text("mine")),
     "holds files sonarmap did not write (extra.txt)"),
    (lambda d: d.write_text("a file"), "is not a directory"),
])
def test_anything_else_is_refused_and_left_alone(tmp_path: Path, make, reason: str) -> None:
    final = tmp_path / "goldens" / "office"
    final.parent.mkdir()
    make(final)
    before = {p: p.read_bytes() for p in ([final] if final.is_file() else final.iterdir())}
    assert reason in (golden_refusal(final) or "")
    with pytest.raises(OutputError, match=reason.split(" (")[0]):
        replace_golden(staged(tmp_path / "new", "N"), final)
    assert {p: p.read_bytes() for p in before} == before


def test_recover_puts_an_old_golden_back_after_a_kill_between_renames(tmp_path: Path) -> None:
    goldens = tmp_path / "goldens"
    goldens.mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    staged(goldens / f".office.old-{dead}-0123abcd", "A")  # renamed aside, new one not in
    staged(goldens / f".corridor.tmp-{dead}-0123abcd", "B")  # a dead update's staging
    assert recover_goldens(goldens) == [goldens / "office"]
    assert sorted(p.name for p in goldens.iterdir()) == ["office"]
    assert set(contents(goldens / "office").values()) >= {"A" * 1000}


def _replace_forever(a: Path, b: Path, final: Path, how: str) -> None:
    """The child's loop: replace the golden with A, then B, until killed."""
    import pipeline.tools.suite.golden_dir as g

    if how == "rename":
        g.exchange = lambda _a, _b: False  # the fallback of systems without an exchange
    while True:
        g.replace_golden(a, final)
        g.replace_golden(b, final)


@pytest.mark.parametrize("how", ["exchange", "rename"])
def test_a_kill_at_any_moment_leaves_the_golden_old_or_new(tmp_path: Path, how: str) -> None:
    """SIGKILL a process replacing a golden back and forth, at 40 moments: each time,
    after recovery, the golden holds all of A or all of B, and nothing else is left."""
    a = staged(tmp_path / "a", "A", size=100_000)
    b = staged(tmp_path / "b", "B", size=100_000)
    goldens = tmp_path / "goldens"
    final = goldens / "office"
    replace_golden(a, final)
    for k in range(40):
        pid = os.fork()  # a child of this process: no interpreter start-up per kill
        if pid == 0:
            try:
                _replace_forever(a, b, final, how)
            finally:
                os._exit(1)
        time.sleep(0.001 + 0.0007 * k)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        recover_goldens(goldens)
        assert contents(final) in (contents(a), contents(b)), f"kill {k}: half-written"
        assert [p.name for p in goldens.iterdir()] == ["office"]
