"""Refresh the goldens of sample_logs/goldens/goldens.toml (``make goldens``).

For each entry: ``sonarmap run`` into a temporary directory, keep what ``regress`` compares
(metrics.json, map.yaml, map.pgm, config.toml) and, where the entry names a ground truth,
``sonarmap evaluate --output evaluation.json`` so regress can hold F1 too. Run from the
repository root; refreshing is deliberate: review the diff of the goldens before committing.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = Path(__file__).resolve().parent
KEEP = ("metrics.json", "map.yaml", "map.pgm", "config.toml")


def sonarmap(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "cli", *args], cwd=ROOT, check=True)


def _read(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(path.read_text())
    return data


def _write(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def main() -> None:
    entries = tomllib.loads((GOLDENS / "goldens.toml").read_text())["golden"]
    for e in entries:
        dest = GOLDENS / e["name"]
        with tempfile.TemporaryDirectory() as tmp:
            run_dir = Path(tmp) / e["name"]
            sonarmap("run", e["log"], "-o", str(run_dir), "--quiet", *e.get("args", []))
            if dest.exists():
                shutil.rmtree(dest)
            dest.mkdir()
            for name in KEEP:
                shutil.copy2(run_dir / name, dest / name)
            # Goldens hold only what reruns reproduce: no timing, no temporary paths.
            metrics = _read(dest / "metrics.json")
            metrics.pop("timing", None)
            _write(dest / "metrics.json", metrics)
            if "truth" in e:
                ev = dest / "evaluation.json"
                sonarmap("evaluate", str(run_dir), "--truth", e["truth"], "--trajectory",
                         e["trajectory"], "--output", str(ev), "--json")
                evaluation = _read(ev)
                evaluation["run_dir"] = str(dest.relative_to(ROOT))
                _write(ev, evaluation)
        print(f"refreshed {dest.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
