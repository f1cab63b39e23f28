"""The method comparison: one log mapped three ways, each scored against the ground truth.

Usage::

    python benchmarks/compare_methods.py [--logs LOG TRUTH [LOG TRUTH ...]]
        [--figure compare.png] [--tolerance 0.10] [--reach M] [--config TOML] [--keep DIR]

Each log is mapped with ``pipeline.run.run`` by (1) the paper's method with feature
correction, (2) the paper's method without it (the paper's ablation) and (3) the classic
log-odds baseline, into a temporary directory (``--keep DIR`` keeps the runs). Each run is
evaluated with :func:`pipeline.evaluate.evaluate_run` against the truth map, with recall
restricted to walls within sensor reach of the true trajectory (``<stem>.truth.csv`` beside
the truth, when present). Prints one Markdown table per log: F1, precision, recall, mean
feature variance (m²), features, readings/s. ``--figure`` writes the three ``map.png``
images side by side (one row per log) with labels.

Defaults: every simulated log under ``sample_logs/`` with a ``<stem>.truth.yaml`` beside
it (one format per simulation: .mcap first); the configuration is ``--config``, else ``sonarmap.toml`` beside the log, else the
defaults. The reach is ``--reach``, else the largest sensor max range in the log or the
configuration.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pipeline.config import Config, load_config

REPO = Path(__file__).resolve().parents[1]
LOG_SUFFIXES = {".mcap", ".bag", ".db3", ".csv", ".txt", ".zst"}

METHODS: tuple[tuple[str, Literal["andersone", "classic"], bool], ...] = (
    ("with_correction", "andersone", True),
    ("without_correction", "andersone", False),
    ("classic", "classic", True),
)
LABELS = {
    "with_correction": "Andersone, with feature correction",
    "without_correction": "Andersone, without correction",
    "classic": "classic log-odds baseline",
}


@dataclass
class Row:
    """One method's scores on one log."""

    key: str
    f1: float
    precision: float
    recall: float
    mean_variance: float | None
    features: int
    readings_per_s: float
    map_png: Path


def default_pairs(root: Path) -> list[tuple[Path, Path]]:
    """(log, truth) for every ``<stem>.truth.yaml`` under ``root`` with a log beside it.

    One log per truth: the same simulation is often written in several formats, and
    mapping identical content twice says nothing new. Preferred: .mcap, .bag, then others.
    """
    rank = {".mcap": 0, ".bag": 1}
    pairs = []
    for truth in sorted(root.rglob("*.truth.yaml")):
        stem = truth.name[: -len(".truth.yaml")]
        logs = [
            p for p in sorted(truth.parent.iterdir())
            if p.name.split(".")[0] == stem and ".truth." not in p.name
            and "waypoints" not in p.name and (p.is_dir() or p.suffix in LOG_SUFFIXES)
        ]
        if logs:
            pairs.append((min(logs, key=lambda p: rank.get(p.suffix, 2)), truth))
    return pairs


def parse_pairs(items: list[str]) -> list[tuple[Path, Path]]:
    if len(items) % 2:
        raise SystemExit("--logs takes pairs: LOG TRUTH [LOG TRUTH ...]")
    return [(Path(items[i]), Path(items[i + 1])) for i in range(0, len(items), 2)]


def load_config_for(log: Path, explicit: Path | None) -> Config:
    """``explicit``, else ``sonarmap.toml`` beside the log, else the defaults."""
    if explicit is not None:
        return load_config(explicit)
    beside = (log if log.is_dir() else log.parent) / "sonarmap.toml"
    return load_config(beside if beside.is_file() else None)


def log_reach(log: Path, cfg: Config) -> float | None:
    """Largest sensor max range, m, in the log's readings or the configuration."""
    from formats import open_log
    from formats.presets import PRESETS
    from pipeline.ingest import survey

    with open_log(log, cfg) as reader:
        sv = survey(reader)
    sc = cfg.sensors
    found = [sv.ranges.max_range_m, sc.max_range]
    found += [m.max_range for m in (*sc.mounts, *PRESETS.get(sc.preset, ()))]
    found = [v for v in found if math.isfinite(v) and v > 0]
    return max(found) if found else None


def compare_log(
    log: Path, truth: Path, work: Path, args: argparse.Namespace
) -> tuple[list[Row], str]:
    """Map ``log`` three ways into ``work`` and evaluate each; returns rows and a caption."""
    from pipeline.evaluate import evaluate_run
    from pipeline.run import run

    cfg = load_config_for(log, args.config)
    stem = truth.name[: -len(".truth.yaml")]
    traj = truth.with_name(f"{stem}.truth.csv")
    trajectory = traj if traj.is_file() else None
    reach = args.reach if args.reach is not None else log_reach(log, cfg)
    rows = []
    scope = ""
    for key, method, correction in METHODS:
        mapper = dataclasses.replace(cfg.mapper, method=method, feature_correction=correction)
        out = work / log.name / key
        result = run(log, out, cfg.replace(mapper=mapper), force=True)
        ev = evaluate_run(out, truth, trajectory=trajectory, tolerance_m=args.tolerance,
                          sensor_reach_m=reach)
        scope = (f"recall within {ev.reach_m:g} m of the true trajectory"
                 if ev.recall_scope == "within_reach" else "recall over all true walls")
        rows.append(Row(
            key, ev.f1, ev.precision, ev.recall, ev.mean_feature_variance_m2,
            int(result.metrics.counts["features"]),
            float(result.metrics.timing.get("readings_per_s", float("nan"))),
            out / "map.png",
        ))
    caption = f"{log.name} vs {truth.name}: tolerance {args.tolerance:g} m, {scope}"
    return rows, caption


def markdown(rows: list[Row], caption: str) -> str:
    def var(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.3e}"

    lines = [
        f"### {caption}",
        "",
        "| method | F1 | precision | recall | mean feature variance (m²) | features | readings/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        feats = str(r.features) if r.key != "classic" else f"{r.features} (none)"
        lines.append(
            f"| {LABELS[r.key]} | {r.f1:.3f} | {r.precision:.3f} | {r.recall:.3f} | "
            f"{var(r.mean_variance)} | {feats} | {r.readings_per_s:,.0f} |"
        )
    return "\n".join(lines)


def figure(results: list[tuple[list[Row], str]], path: Path, height: int = 360) -> None:
    """The map.png images of each log in a row, scaled to ``height`` px, labelled."""
    from PIL import Image, ImageDraw, ImageFont

    from formats.writers.atomic import atomic_write_bytes

    pad, label_h = 8, 36
    font = ImageFont.load_default(size=18)
    rows_img = []
    for rows, caption in results:
        tiles = []
        for r in rows:
            with Image.open(r.map_png) as src:
                rgb = src.convert("RGB")
            w = max(1, round(rgb.width * height / rgb.height))
            tiles.append((rgb.resize((w, height), Image.Resampling.LANCZOS), r))
        width = sum(t.width for t, _ in tiles) + pad * (len(tiles) + 1)
        canvas = Image.new("RGB", (width, height + 2 * label_h + pad), "white")
        draw = ImageDraw.Draw(canvas)
        draw.text((pad, 6), caption, fill="black", font=font)
        x = pad
        for tile, r in tiles:
            canvas.paste(tile, (x, label_h))
            draw.text((x, label_h + height + 6), f"{LABELS[r.key]}: F1 {r.f1:.3f}",
                      fill="black", font=font)
            x += tile.width + pad
        rows_img.append(canvas)
    full = Image.new("RGB", (max(i.width for i in rows_img), sum(i.height for i in rows_img)),
                     "white")
    y = 0
    for img in rows_img:
        full.paste(img, (0, y))
        y += img.height
    buf = io.BytesIO()
    full.save(buf, format="PNG", optimize=True)
    atomic_write_bytes(path, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", nargs="+", metavar="PATH", help="LOG TRUTH pairs")
    ap.add_argument("--figure", type=Path, help="write the side-by-side maps to this PNG")
    ap.add_argument("--tolerance", type=float, default=0.10, help="match distance, m")
    ap.add_argument("--reach", type=float, help="sensor reach for recall, m")
    ap.add_argument("--config", type=Path, help="configuration TOML for every log")
    ap.add_argument("--keep", type=Path, help="keep the run directories under this directory")
    args = ap.parse_args(argv)

    from formats.errors import SonarmapError

    pairs = parse_pairs(args.logs) if args.logs else default_pairs(REPO / "sample_logs")
    if not pairs:
        print("no (log, truth) pairs: simulate sample logs first or pass --logs", file=sys.stderr)
        return 1
    results = []
    with tempfile.TemporaryDirectory(prefix="sonarmap-compare-") as tmp:
        work = args.keep if args.keep is not None else Path(tmp)
        for log, truth in pairs:
            try:
                rows, caption = compare_log(log, truth, work, args)
            except SonarmapError as err:
                print(f"{log}: skipped: {err}", file=sys.stderr)
                continue
            results.append((rows, caption))
            print(markdown(rows, caption), end="\n\n", flush=True)
        if args.figure is not None and results:
            figure(results, args.figure)
            print(f"figure: {args.figure}")
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
