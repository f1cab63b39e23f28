"""Issue 58, "messages that mislead": each says what is wrong and where. (A nav2 YAML's
``resolution: 5e-2``: test_side_files.py; a parent that refuses OUT:
test_read_only_parent.py.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT

CONFIG = ('[grid]\nresolution = 0.1\n\n[[sensors.mounts]]\nname = "s0"\nyaw_deg = 90.0\n{extra}'
          '\n[[sensors.mounts]]\nname = "s1"\nyaw_deg = -90.0\n')


def _log(path: Path, *, fov: str = "0.5", max_range: str = "5.0", nan_fov_every: int = 0,
         rng: str = "1.5") -> Path:
    rows = ["t,x,y,yaw,sensor,range,fov,min_range,max_range,scan"]
    for i in range(200):
        f = "nan" if nan_fov_every and i % nan_fov_every == 7 else fov
        r = rng if i % 7 == 0 else "1.5"
        rows.append(f"{0.05 * i:.3f},{0.02 * i},0,0,s{i % 2},{r},{f},0.1,{max_range},{i // 2}")
    path.write_text("\n".join(rows) + "\n")
    return path


def _run(tmp_path: Path, log: Path, extra: str = "") -> tuple[int, str]:
    cfg = tmp_path / "c.toml"
    cfg.write_text(CONFIG.format(extra=extra))
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(tmp_path / "out"), "-c", str(cfg),
                                   "-q"])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stderr


def test_a_negative_max_range_is_not_reported_as_the_extent(tmp_path: Path) -> None:
    log = _log(tmp_path / "neg.csv", max_range="-5.0")  # a logged negative limit: none
    code, err = _run(tmp_path, log)
    assert code == 1
    assert err == (f"sonarmap: error: {log}: cannot size the grid: no sensor reports a max"
                   " range > 0; set [grid] extent or [sensors] max_range\n")
    code, err = _run(tmp_path, _log(tmp_path / "ok.csv"), extra="max_range = -1.0\n")
    assert code == 1
    assert "'sensors.mounts[0].min_range/max_range' must be >= 0, got (0.0, -1.0)" in err
    assert "extent" not in err


def test_a_nan_beam_width_on_a_few_readings_is_counted_not_called_missing(
    tmp_path: Path,
) -> None:
    log = _log(tmp_path / "nanfov.csv", nan_fov_every=50)
    code, err = _run(tmp_path, log)
    assert code == 1
    assert err.startswith(f"sonarmap: error: {log}: no beam width (fov) for sensor(s) s1: 4 of"
                          " their ")
    assert "readings in this part of the log carry a NaN fov" in err
    assert "carries none" not in err


def test_numpy_warnings_do_not_reach_stderr(tmp_path: Path) -> None:
    """Ranges at the edge of a float (1e300 m, beyond max range): mapped, exit 0, and
    stderr holds nothing (a separate process: pytest would capture Python's warnings)."""
    log = _log(tmp_path / "huge.csv", rng="1e300")
    cfg = tmp_path / "c.toml"
    cfg.write_text(CONFIG.format(extra=""))
    res = subprocess.run([sys.executable, "-W", "default", "-m", "cli", "run", str(log), "-o",
                          str(tmp_path / "out"), "-c", str(cfg), "-q"],
                         capture_output=True, text=True, check=False, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
