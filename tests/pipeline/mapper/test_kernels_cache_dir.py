"""Where numba's kernel cache goes (kernels/cache_dir.py): numba's own places when writable,
``NUMBA_CACHE_DIR`` when the user set it, a temp directory when nothing else is writable."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

from pipeline.mapper.kernels.cache_dir import KERNELS_DIR, choose_cache_dir


def _choose(env: dict[str, str], writable: set[Path], tmp: Path) -> str | None:
    return choose_cache_dir(env, tmp / "kernels", tmp / "user", tmp / "temp",
                            writable=lambda p: p in writable)


def test_user_setting_wins(tmp_path: Path) -> None:
    assert _choose({"NUMBA_CACHE_DIR": "/somewhere"}, set(), tmp_path) is None


def test_numba_defaults_kept_when_writable(tmp_path: Path) -> None:
    assert _choose({}, {tmp_path / "kernels" / "__pycache__"}, tmp_path) is None
    assert _choose({}, {tmp_path / "user"}, tmp_path) is None  # read-only install, ~/.cache ok


def test_temp_directory_when_nothing_is_writable(tmp_path: Path) -> None:
    chosen = _choose({}, set(), tmp_path)
    assert chosen is not None
    assert Path(chosen).parent == tmp_path / "temp"
    assert Path(chosen).name.startswith("sonarmap-numba-cache-")


def test_kernels_run_with_a_cache_directory_set(tmp_path: Path) -> None:
    """A process with NUMBA_CACHE_DIR compiles into it (and nowhere else) and maps."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    code = ("from pipeline.mapper.kernels.cone import max_sector_spans; "
            "print(max_sector_spans(1.0, 0.05))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout
    assert int(out) == 2 * (math.ceil(2.0 / 0.05) + 3)
    assert any(p.suffix == ".nbi" for p in (tmp_path / "cache").rglob("*"))
    assert KERNELS_DIR.name == "kernels"
