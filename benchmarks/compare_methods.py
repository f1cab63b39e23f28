"""The method comparison: every log mapped by every method and by OctoMap, side by side.

Usage::

    python benchmarks/compare_methods.py [--logs LOG TRUTH [LOG TRUTH ...]]
        [--figure compare.png] [--tolerance 0.10] [--reach M] [--config TOML] [--keep DIR]
        [--summary FILE.md]

Each log is mapped with ``pipeline.run.run`` by (1) the default method (specular echo
attribution, ALGORITHM.md §10; and §9's echo attribution beside it), (2) the paper's method with feature correction, (3) the paper's method
without it (the paper's ablation), (4) the classic log-odds grid, into a temporary
directory (``--keep DIR`` keeps the runs), and (5) by OctoMap from the same readings
(:mod:`benchmarks.octomap_baseline`; skipped without the ``bench`` extra). Every map is
scored by the same code as ``sonarmap evaluate`` (:func:`pipeline.tools.evaluate.evaluate_maps`)
against the truth map, with recall restricted to walls within sensor reach of the true
trajectory (``<stem>.truth.csv`` beside the truth, when present). Prints one Markdown
table per log (F1, precision, recall, mean feature variance (m²), features, readings/s)
and, at the end, one summary table of F1 for every log and method with the default's
margin over OctoMap (``--summary`` also writes it to a file); logs named
``<name>-realistic.*`` (the realistic sonar, docs/SONAR_PHYSICS.md) get a second table
beside the ideal ``<name>.*``: default and OctoMap with either sonar. ``--figure`` writes the
maps side by side (one row per log) with labels.

Defaults: every simulated log under ``sample_logs/`` with a ``<stem>.truth.yaml`` beside
it (one format per simulation: .mcap first); the configuration is ``--config``, else ``sonarmap.toml`` beside the log, else the
defaults. The reach is ``--reach``, else the largest sensor max range in the log or the
configuration.

``--drifted [--cases NAME ...] [--config TOML] [--keep DIR]`` runs the drifted-odometry
rows instead (issue 17): the office, corridor and orchard simulations and the five
buildings (Intel lab, Freiburg 101, Örebro, FHW, Belgioioso) emulated with 3 % scale error
and 0.8°/m heading bias, each mapped by the default method on true poses, on the drifted odometry, refined
(``--refine-poses``; ``--config`` sets its ``[pose_refinement]``) and refined from true
poses; F1, ATE before/after and run seconds per case. ``--sonar-model realistic`` simulates
and emulates them with the realistic sonar (docs/SONAR_PHYSICS.md) instead of the ideal one,
the true-pose runs then ``make compare``'s ``build/compare/<name>-realistic.mcap``.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from pipeline.config import Config, load_config
from pipeline.drift import DriftModel
from pipeline.methods import Method

REPO = Path(__file__).resolve().parents[1]
LOG_SUFFIXES = {".mcap", ".bag", ".db3", ".csv", ".txt", ".zst"}

METHODS: tuple[tuple[str, Method, bool], ...] = (
    ("default", Method.FORWARD, True),
    ("specular", Method.SPECULAR, True),
    ("attribution", Method.ATTRIBUTION, True),
    ("with_correction", Method.ANDERSONE, True),
    ("without_correction", Method.ANDERSONE, False),
    ("classic", Method.CLASSIC, True),
)
LABELS = {
    "default": "sonarmap default (§11: specular echo attribution, detection measured)",
    "specular": "specular echo attribution (§10)",
    "attribution": "echo attribution (§9)",
    "with_correction": "Andersone, with feature correction",
    "without_correction": "Andersone, without correction",
    "classic": "classic log-odds grid",
    "octomap": "OctoMap",
}
# Shown in the figure (the ablation without correction is in the tables only).
FIGURE_KEYS = ("default", "attribution", "with_correction", "classic", "octomap")
# Short captions: a narrow map's tile is only ~60 px wide.
FIGURE_LABELS = {"default": "default", "attribution": "§9", "with_correction": "paper",
                 "classic": "classic", "octomap": "OctoMap"}


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
    f1_dilated: float = math.nan  # F1 with the map's walls grown by one cell (thickness check)
    f1_thinned: float = math.nan  # F1 with the map's walls thinned to one cell
    note: str = ""  # OctoMap: which variant and classification scored best


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
    from pipeline.stages.ingest import survey

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
    from formats.writers.nav2_map import load_nav2_map
    from formats.writers.trajectory_csv import read_trajectory
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    cfg = load_config_for(log, args.config)
    stem = truth.name[: -len(".truth.yaml")]
    traj = truth.with_name(f"{stem}.truth.csv")
    trajectory = traj if traj.is_file() else None
    reach = args.reach if args.reach is not None else log_reach(log, cfg)
    rows = []
    scope = ""
    poses = None if trajectory is None else read_trajectory(trajectory).xy
    ref = load_nav2_map(truth)
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
            *thickness_f1(load_nav2_map(out / "map.yaml"), ref, poses, ev.reach_m, args.tolerance),
        ))
    octo = octomap_row(log, cfg, truth, trajectory, reach, work / log.name, args.tolerance)
    if octo is not None:
        rows.append(octo)
    caption = f"{log.name} vs {truth.name}: tolerance {args.tolerance:g} m, {scope}"
    return rows, caption


def octomap_row(
    log: Path, cfg: Config, truth: Path, trajectory: Path | None, reach: float | None,
    work: Path, tolerance: float,
) -> Row | None:
    """OctoMap's map of the same readings, scored like the others: the best of its variants
    (max-range readings skipped or as free rays) and classifications (p > 0.5, nav2's
    thresholds), see :mod:`benchmarks.octomap_baseline`; None without octomap."""
    from benchmarks import octomap_baseline as ob
    from formats.writers.nav2_map import load_nav2_map
    from formats.writers.trajectory_csv import read_trajectory
    from pipeline.tools.evaluate import evaluate_maps

    if not ob.available():
        print(f"{log.name}: OctoMap row skipped (pip install -e '.[bench]')", file=sys.stderr)
        return None
    ref = load_nav2_map(truth)
    poses = None if trajectory is None else read_trajectory(trajectory).xy
    best: tuple[dict[str, float], np.ndarray, str] | None = None
    grid = None
    checks = []
    for variant, max_range_free in ob.VARIANTS.items():
        tree, grid = ob.octomap_tree(log, cfg, max_range_free=max_range_free)
        prob = ob.leaves_on_grid(tree, grid)
        differ, known = ob.readback_mismatch(tree, grid, prob)
        checks.append(f"{differ} of {known:,} known cells differ from tree.search")
        for label, (occupied_above, free_below) in ob.THRESHOLDS.items():
            cls = ob.classes(prob, occupied_above, free_below)
            values, _ = evaluate_maps(cls, grid, ref.classes, ref.grid, tolerance_m=tolerance,
                                      poses_xy=poses, reach_m=reach,
                                      feature_xy=np.zeros((0, 2)))
            if best is None or values["f1"] > best[0]["f1"]:
                best = (values, cls, f"{variant}, {label.removeprefix('OctoMap ')}")
    assert best is not None and grid is not None
    values, cls, note = best
    note += f" (read-back: {'; '.join(checks)})"
    png = work / "octomap.png"
    classes_png(cls, png)
    grown, thin = thickness_f1(SimpleNamespace(classes=cls, grid=grid), ref, poses, reach,
                               tolerance)
    return Row("octomap", values["f1"], values["precision"], values["recall"], None, 0,
               float("nan"), png, grown, thin, note)


def dilated(cls: np.ndarray) -> np.ndarray:
    """A trinary map with every occupied cell grown by one cell (its 3×3 neighbourhood)."""
    from scipy.ndimage import binary_dilation

    from pipeline.tools.evaluate import OCCUPIED

    out = cls.copy()
    out[binary_dilation(cls == OCCUPIED, structure=np.ones((3, 3), bool))] = OCCUPIED
    return out


def thinned(cls: np.ndarray) -> np.ndarray:
    """A trinary map with its occupied cells thinned to one-cell lines (the cells thinning
    removes become free)."""
    from pipeline.tools.evaluate import FREE, OCCUPIED
    from pipeline.tools.wall_matching import thin

    occupied = cls == OCCUPIED
    out = cls.copy()
    out[occupied & ~thin(occupied)] = FREE
    return out


def thickness_f1(run_map: object, ref: object, poses: np.ndarray | None, reach: float | None,
                 tolerance: float) -> tuple[float, float]:
    """F1 of a map (``.classes``, ``.grid``) with its walls grown by one cell and with them
    thinned to one cell, scored as the map itself."""
    from pipeline.tools.evaluate import evaluate_maps

    out = []
    for changed in (dilated, thinned):
        values, _ = evaluate_maps(changed(run_map.classes), run_map.grid,  # type: ignore[attr-defined]
                                  ref.classes, ref.grid, tolerance_m=tolerance,  # type: ignore[attr-defined]
                                  poses_xy=poses, reach_m=reach, feature_xy=np.zeros((0, 2)))
        out.append(float(values["f1"]))
    return out[0], out[1]


def classes_png(cls: np.ndarray, path: Path) -> None:
    """A trinary map as a grey PNG (black occupied, white free, grey unknown; north up)."""
    from PIL import Image

    from pipeline.tools.evaluate import FREE, OCCUPIED

    grey = np.full(cls.shape, 205, dtype=np.uint8)
    grey[cls == FREE] = 254
    grey[cls == OCCUPIED] = 0
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(grey[::-1]).save(path)


def markdown(rows: list[Row], caption: str) -> str:
    def var(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.3e}"

    def rate(v: float) -> str:
        return "–" if math.isnan(v) else f"{v:,.0f}"

    lines = [
        f"### {caption}",
        "",
        "| method | F1 | precision | recall | mean feature variance (m²) | features | readings/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        feats = str(r.features) if r.key not in ("classic", "octomap") else "(none)"
        lines.append(
            f"| {LABELS[r.key]} | {r.f1:.3f} | {r.precision:.3f} | {r.recall:.3f} | "
            f"{var(r.mean_variance)} | {feats} | {rate(r.readings_per_s)} |"
        )
    return "\n".join(lines)


def summary(results: list[tuple[list[Row], str]]) -> str:
    """One table: F1 (precision / recall) of every method on every log, the paper's metric
    with and without correction, and the default's F1 margin over OctoMap."""
    keys = ["default", "specular", "attribution", "with_correction", "without_correction", "classic", "octomap"]
    head = ["log", *(LABELS[k] for k in keys), "default − OctoMap",
            "mean feature variance with / without correction (m²)"]
    lines = ["| " + " | ".join(head) + " |", "|---" + "|---:" * (len(head) - 1) + "|"]
    for rows, caption in results:
        by = {r.key: r for r in rows}
        cells = [caption.split(" vs ")[0]]
        for k in keys:
            r = by.get(k)
            cells.append("–" if r is None else
                         f"**{r.f1:.3f}** ({r.precision:.2f} / {r.recall:.2f})"
                         if k == "default" else f"{r.f1:.3f} ({r.precision:.2f} / {r.recall:.2f})")
        margin = (by["default"].f1 - by["octomap"].f1) if "octomap" in by else None
        cells.append("–" if margin is None else f"{margin:+.3f}")
        on, off = by["with_correction"].mean_variance, by["without_correction"].mean_variance
        cells.append("–" if on is None or off is None else f"{on:.2e} / {off:.2e}")
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", sonar_models(results)]
    lines += ["", "OctoMap's best variant per log: " + "; ".join(
        f"{caption.split(' vs ')[0]}: {r.note}" for rows, caption in results
        for r in rows if r.key == "octomap"), "", thickness(results)]
    return "\n".join(lines)


REALISTIC_SUFFIX = "-realistic"


def sonar_models(results: list[tuple[list[Row], str]]) -> str:
    """The default's and OctoMap's F1 with the ideal and the realistic sonar of the same
    building or world side by side: a log ``<name>-realistic.*`` (``--sonar-model
    realistic``, docs/SONAR_PHYSICS.md) pairs with the log named ``<name>.*``."""
    by_name = {caption.split(" vs ")[0].split(".")[0]: {r.key: r for r in rows}
               for rows, caption in results}
    lines = ["| log | default, ideal sonar | OctoMap, ideal | lead, ideal "
             "| default, realistic sonar | OctoMap, realistic | lead, realistic |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, real in by_name.items():
        if not name.endswith(REALISTIC_SUFFIX):
            continue
        base = name.removesuffix(REALISTIC_SUFFIX)
        ideal = by_name.get(base, {})
        cells = [base]
        for rows in (ideal, real):
            d, o = rows.get("default"), rows.get("octomap")
            cells += ["–" if d is None else f"{d.f1:.3f}", "–" if o is None else f"{o.f1:.3f}",
                      "–" if d is None or o is None else f"{d.f1 - o.f1:+.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) if len(lines) > 2 else ""


def thickness(results: list[tuple[list[Row], str]]) -> str:
    """F1 with every method's walls grown by one cell and thinned to one cell, beside its
    own: a scorer that neither rewards thick walls nor thin ones gains (almost) nothing
    from either."""
    keys = ["default", "specular", "attribution", "with_correction", "without_correction", "classic", "octomap"]
    head = ["log (F1: gain grown one cell / thinned to one cell)", *(LABELS[k] for k in keys)]
    lines = ["| " + " | ".join(head) + " |", "|---" + "|---:" * (len(head) - 1) + "|"]
    worst = {"grown": -math.inf, "thinned": -math.inf}
    for rows, caption in results:
        by = {r.key: r for r in rows}
        cells = [caption.split(" vs ")[0]]
        for k in keys:
            r = by.get(k)
            if r is None:
                cells.append("–")
                continue
            grown, thin = r.f1_dilated - r.f1, r.f1_thinned - r.f1
            worst["grown"] = max(worst["grown"], grown)
            worst["thinned"] = max(worst["thinned"], thin)
            cells.append(f"{r.f1:.3f}: {grown:+.3f} / {thin:+.3f}")
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"Largest gain from growing the walls: {worst['grown']:+.3f} F1; "
                 f"from thinning them: {worst['thinned']:+.3f} F1.")
    return "\n".join(lines)


def figure(results: list[tuple[list[Row], str]], path: Path, height: int = 180) -> None:
    """The map.png images of each log in a row, scaled to ``height`` px, labelled; saved with a
    256-colour palette so the figure stays small in the repository."""
    from PIL import Image, ImageDraw, ImageFont

    from formats.writers.atomic import atomic_write_bytes

    pad, label_h = 8, 36
    font = ImageFont.load_default(size=14)
    rows_img = []
    for rows, caption in results:
        tiles = []
        for r in (r for r in rows if r.key in FIGURE_KEYS):
            with Image.open(r.map_png) as src:
                rgb = src.convert("RGB")
            w = max(1, round(rgb.width * height / rgb.height))
            tiles.append((rgb.resize((w, height), Image.Resampling.LANCZOS), r))
        texts = [f"{FIGURE_LABELS[r.key]} {r.f1:.3f}" for _, r in tiles]
        slots = [max(t.width, math.ceil(font.getlength(text)))
                 for (t, _), text in zip(tiles, texts, strict=True)]
        width = max(sum(slots) + pad * (len(tiles) + 1), math.ceil(font.getlength(caption)) + pad)
        canvas = Image.new("RGB", (width, height + 2 * label_h + pad), "white")
        draw = ImageDraw.Draw(canvas)
        draw.text((pad, 6), caption, fill="black", font=font)
        x = pad
        for (tile, _), text, slot in zip(tiles, texts, slots, strict=True):
            canvas.paste(tile, (x, label_h))
            draw.text((x, label_h + height + 6), text, fill="black", font=font)
            x += slot + pad
        rows_img.append(canvas)
    full = Image.new("RGB", (max(i.width for i in rows_img), sum(i.height for i in rows_img)),
                     "white")
    y = 0
    for img in rows_img:
        full.paste(img, (0, y))
        y += img.height
    buf = io.BytesIO()
    full.quantize(colors=256, dither=Image.Dither.NONE).save(buf, format="PNG", optimize=True)
    atomic_write_bytes(path, buf.getvalue())


# ------------------------------------------------------------------ drifted odometry (issue 17)
# Separate from the method comparison above: each drifted case is mapped with the default
# method three ways — true poses, drifted odometry, drifted odometry + --refine-poses — and
# scored by F1 and, against the true trajectory, ATE (pipeline.tools.trajectory_error). F1 is
# given twice: in the truth's frame, and "aligned" — after moving the map by the rigid
# motion that lays its trajectory onto the true one (pipeline.tools.evaluate, ``aligned``): a
# drifted run's frame is anchored where its odometry started, and a heading error in the
# first metres turns the whole map without changing its shape.
# The "-odometry" cases are real drift: the building's own wheel odometry (CARMEN ODOM
# lines, ``emulate --raw-odometry``) in place of its corrected poses.

DRIFT_SCALE = 0.03
DRIFT_BIAS_DEG_PER_M = 0.8
# --drift-model walk: wheel odometry's random walk (issue 63): -2 % scale, -0.5°/m heading
# bias, a heading random walk of 0.01 rad/√m and 0.01 m/√m of position noise.
WALK = DriftModel(-0.02, -0.5, noise_xy=0.01, heading_walk=0.01)


@dataclass
class DriftRow:
    """One drifted case: F1 with true / drifted / refined poses, ATE, seconds."""

    name: str
    f1_true: float
    f1_drifted: float
    f1_refined: float
    f1_true_refined: float
    ate_drifted: float
    ate_refined: float
    seconds_unrefined: float
    seconds_refined: float
    cpu_unrefined: float  # CPU seconds of the whole run() call (the machine may be loaded)
    cpu_refined: float
    found: tuple[float, float]  # (scale error, heading bias °/m) refinement applied, drifted
    found_true: tuple[float, float]  # ... on the true poses (truth: 0, 0)
    f1_drifted_aligned: float = math.nan  # after the trajectory's SE(2) alignment
    f1_refined_aligned: float = math.nan


SYNTHETIC_DRIFT_CASES = ("office", "corridor", "orchard", "intel-lab", "freiburg-101", "orebro",
                         "fhw", "belgioioso")
REAL_ODOMETRY_CASES = ("intel-lab-odometry", "freiburg-101-odometry", "fhw-odometry")
DRIFT_CASES = SYNTHETIC_DRIFT_CASES + REAL_ODOMETRY_CASES


def _drift_cases(work: Path, names: tuple[str, ...] = DRIFT_CASES, walk: bool = False,
                 drift_seed: int = 0, sonar_model: str = "ideal"
                 ) -> list[tuple[str, Path, Path, Path, Path]]:
    """(name, true-pose log, drifted log, truth map, truth trajectory) per case: the office,
    corridor and orchard simulations and the five real buildings (the Belgioioso castle
    beside make compare's four), emulated with drift applied to their corrected poses
    (:func:`drifted_case`; ``drift_seed`` draws the buildings' drift noise; ``sonar_model``:
    the sonar simulated or emulated, docs/SONAR_PHYSICS.md)."""
    drift = WALK if walk else DriftModel(DRIFT_SCALE, DRIFT_BIAS_DEG_PER_M)
    work.mkdir(parents=True, exist_ok=True)
    cases = []
    for case in names:
        seed = f"_seed{drift_seed}" if drift_seed else ""
        kind = "walk" if walk else "drifted"
        drifted = work / f"{case}_{kind}{seed}{_sonar_suffix(sonar_model)}.mcap"
        clean, truth, traj = drifted_case(case, drifted, drift, drift_seed,
                                          sonar_model=sonar_model)
        cases.append((case, clean, drifted, truth, traj))
    return cases


def drifted_case(case: str, drifted: Path, drift: DriftModel, drift_seed: int = 0,
                 preset: str | None = None, sonar_model: str = "ideal"
                 ) -> tuple[Path, Path, Path]:
    """(true-pose log, truth map, truth trajectory) of a drifted case, its drifted log
    written to ``drifted`` when missing: a world of ``sample_logs/worlds`` simulated again
    with ``drift`` (the simulation's seed draws its noise; its true run the sample log, or
    for a world without one, or with ``preset``'s sonars, the same simulation undrifted
    beside ``drifted``), a building emulated with ``drift`` applied to its
    corrected poses (``drift_seed``), or for ``<building>-odometry`` its own wheel odometry
    (the Radish logs' true-pose runs are ``make compare``'s ``build/compare/<name>.mcap``,
    emulated here when missing). ``preset``: the sonars simulated or emulated as that
    preset's ring (formats/presets.py), its true-pose run beside ``drifted``.
    ``sonar_model``: ``"ideal"`` (the sample logs' sonar) or ``"realistic"``
    (docs/SONAR_PHYSICS.md), the true-pose run then ``make compare``'s
    ``build/compare/<name>-realistic.mcap`` (simulated or emulated there when missing)."""
    from pipeline.tools.emulate import EmulateOptions, run_emulation
    from pipeline.tools.simulate import SimOptions, run_simulation

    real = case.endswith("-odometry")
    name = case.removesuffix("-odometry")
    world = REPO / "sample_logs" / "worlds" / f"{name}.toml"
    if world.exists() and not real:
        # a sample log's true run where there is one, else the same simulation undrifted
        from formats.presets import PRESETS

        clean = REPO / "sample_logs" / name / f"{name}.mcap"
        sim = SimOptions(seed=1, speed=0.5, ring_rate_hz=5.0, sonar_model=sonar_model)
        if preset is not None:  # the world's sonars as that preset's ring
            sim = dataclasses.replace(sim, mounts=PRESETS[preset])
            clean = drifted.with_name(f"{name}-{preset}{_sonar_suffix(sonar_model)}.mcap")
        elif sonar_model != "ideal":  # make compare's simulation (the same options)
            clean = REPO / "build" / "compare" / f"{name}{_sonar_suffix(sonar_model)}.mcap"
            clean.parent.mkdir(parents=True, exist_ok=True)
        elif not clean.exists():
            clean = drifted.with_name(f"{name}.mcap")
        if not clean.exists():
            run_simulation(world, clean, "mcap", options=sim)
        if not drifted.exists():
            run_simulation(world, drifted, "mcap",
                           options=dataclasses.replace(
                               sim, drift_scale=drift.scale_error,
                               drift_heading_bias_deg_per_m=drift.heading_bias_deg_per_m,
                               drift_xy=drift.noise_xy, drift_yaw=drift.noise_yaw,
                               drift_heading_walk=drift.heading_walk))
        return (clean, clean.with_name(f"{clean.stem}.truth.yaml"),
                clean.with_name(f"{clean.stem}.truth.csv"))
    suffix = _sonar_suffix(sonar_model)
    if name == "intel-lab" and sonar_model == "ideal":
        src = REPO / "sample_logs" / "intel-lab" / "intel-corrected.log.gz"
        clean = REPO / "sample_logs" / "intel-lab" / "intel.mcap"
    elif name in ("intel-lab", "freiburg-101", "orebro", "fhw", "belgioioso"):
        stem = "intel" if name == "intel-lab" else name
        src = (REPO / "sample_logs" / "intel-lab" / "intel-corrected.log.gz"
               if name == "intel-lab" else
               REPO / "sample_logs" / "radish" / f"{name}-corrected.log.gz")
        clean = REPO / "build" / "compare" / f"{stem}{suffix}.mcap"
        if not clean.exists():
            clean.parent.mkdir(parents=True, exist_ok=True)
            run_emulation(src, clean, "mcap", options=EmulateOptions(sonar_model=sonar_model))
    else:
        raise SystemExit(f"unknown drifted case {case!r}; known: {', '.join(DRIFT_CASES)}")
    if preset is not None:
        clean = drifted.with_name(f"{name}-{preset}{suffix}.mcap")
        if not clean.exists():
            run_emulation(src, clean, "mcap",
                          options=EmulateOptions(preset=preset, sonar_model=sonar_model))
    truth = clean.with_name(f"{clean.stem}.laser.yaml")
    traj = clean.with_name(f"{clean.stem}.truth.csv")
    if not drifted.exists():
        opts = (EmulateOptions(raw_odometry=True, preset=preset, sonar_model=sonar_model)
                if real else EmulateOptions(drift=drift, drift_seed=drift_seed, preset=preset,
                                            sonar_model=sonar_model))
        run_emulation(src, drifted, "mcap", options=opts)
    return clean, truth, traj


def _sonar_suffix(sonar_model: str) -> str:
    """A log's name suffix for its sonar model: none for the ideal one (the sample logs),
    ``-realistic`` (``make compare``'s ``<name>-realistic.mcap``)."""
    return "" if sonar_model == "ideal" else f"-{sonar_model}"


def drifted_comparison(work: Path, tolerance: float, names: tuple[str, ...] = DRIFT_CASES,
                       config: Path | None = None, walk: bool = False,
                       drift_seed: int = 0, sonar_model: str = "ideal") -> list[DriftRow]:
    """Map and score every drifted case (see the section comment); ``config`` (TOML) sets
    the refined runs' ``[pose_refinement]`` (enabled either way); ``walk``: the random-walk
    drift (``WALK``) instead of the systematic one; ``drift_seed``: the buildings' drift
    noise draw; ``sonar_model``: the sonar the cases are simulated or emulated with."""
    return score_drift_cases(_drift_cases(work, names, walk, drift_seed, sonar_model), work,
                             tolerance, config)


DRIFTED_MAX_CELLS = 100_000_000  # ~3.2 GB at ~32 bytes a cell


def score_drift_cases(cases: list[tuple[str, Path, Path, Path, Path]], work: Path,
                      tolerance: float, config: Path | None = None) -> list[DriftRow]:
    """Map and score ``cases`` — (name, true-pose log, drifted log, truth map, truth
    trajectory) — with true poses, drifted, refined and true poses refined, under ``work``."""
    from pipeline.config import Config
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    rows = []
    chosen = load_config(config).pose_refinement if config is not None else Config().pose_refinement
    refine = Config(pose_refinement=dataclasses.replace(chosen, enabled=True))
    # A drifted odometry's box can be several times the building's (the Freiburg campus:
    # 736 x 284 m, 84 M cells at 5 cm): its unrefined map may take more than max_cells.
    unrefined = Config(grid=dataclasses.replace(Config().grid, max_cells=DRIFTED_MAX_CELLS))
    for name, clean, drifted, truth, traj in cases:
        f1, f1_aligned, ate, secs, cpu, found = {}, {}, {}, {}, {}, {}
        for key, log, cfg in (("true", clean, Config()), ("drifted", drifted, unrefined),
                              ("refined", drifted, refine), ("true_refined", clean, refine)):
            out = work / name / key
            c0 = time.process_time()
            result = run(log, out, cfg, force=True)
            cpu[key] = time.process_time() - c0
            pr = result.metrics.pose_refinement or {}
            found[key] = (float(pr.get("search_scale_error", math.nan)),
                          float(pr.get("search_heading_bias_deg_per_m", math.nan)))
            ev = evaluate_run(out, truth, trajectory=traj, tolerance_m=tolerance,
                              truth_trajectory=traj)
            f1[key] = ev.f1
            f1_aligned[key] = float(ev.aligned["f1"]) if ev.aligned else math.nan
            ate[key] = float(ev.trajectory_error["ate_rmse_m"]) if ev.trajectory_error else math.nan
            secs[key] = float(result.metrics.timing["stage_seconds"]["total"])
        rows.append(DriftRow(name, f1["true"], f1["drifted"], f1["refined"], f1["true_refined"],
                             ate["drifted"], ate["refined"], secs["drifted"], secs["refined"],
                             cpu["drifted"], cpu["refined"], found["refined"],
                             found["true_refined"], f1_aligned["drifted"], f1_aligned["refined"]))
        print(f"{name}: done", file=sys.stderr, flush=True)
    return rows


def drift_markdown(rows: list[DriftRow]) -> str:
    lines = [
        f"| drifted case ({DRIFT_SCALE:.0%} scale, {DRIFT_BIAS_DEG_PER_M:g}°/m, or the real "
        "odometry) | F1 true poses | F1 drifted | F1 refined | refined/true "
        "| F1 aligned: drifted → refined | aligned refined/true | F1 true poses refined "
        "| ATE drifted (m) "
        "| ATE refined (m) | ATE ratio | scale, bias found: drifted / true poses "
        "| s unrefined | s refined | CPU s unrefined | CPU s refined |",
        "|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.name} | {r.f1_true:.3f} | {r.f1_drifted:.3f} | {r.f1_refined:.3f} | "
            f"{r.f1_refined / r.f1_true:.2f} | {r.f1_drifted_aligned:.3f} → "
            f"{r.f1_refined_aligned:.3f} | {r.f1_refined_aligned / r.f1_true:.2f} | "
            f"{r.f1_true_refined:.3f} | {r.ate_drifted:.3f} | "
            f"{r.ate_refined:.3f} | {r.ate_drifted / max(r.ate_refined, 1e-9):.1f}× | "
            f"{r.found[0]:+.3f}, {r.found[1]:.2f}°/m / {r.found_true[0]:+.3f}, "
            f"{r.found_true[1]:.2f}°/m | {r.seconds_unrefined:.1f} | {r.seconds_refined:.1f} | "
            f"{r.cpu_unrefined:.1f} | {r.cpu_refined:.1f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", nargs="+", metavar="PATH", help="LOG TRUTH pairs")
    ap.add_argument("--figure", type=Path, help="write the side-by-side maps to this PNG")
    ap.add_argument("--tolerance", type=float, default=0.10, help="match distance, m")
    ap.add_argument("--reach", type=float, help="sensor reach for recall, m")
    ap.add_argument("--config", type=Path, help="configuration TOML for every log (with "
                    "--drifted: its [pose_refinement] for the refined runs)")
    ap.add_argument("--keep", type=Path, help="keep the run directories under this directory")
    ap.add_argument("--summary", type=Path, help="also write the summary table to this file")
    ap.add_argument("--drifted", action="store_true",
                    help="only the drifted-odometry rows (true / drifted / refined poses)")
    ap.add_argument("--cases", nargs="+", default=list(DRIFT_CASES), choices=DRIFT_CASES,
                    help="with --drifted: these cases only (default: all)")
    ap.add_argument("--drift-model", choices=("systematic", "walk"), default="systematic",
                    help="with --drifted: 3 %% scale and 0.8°/m (systematic) or wheel "
                    "odometry's random walk (walk: -2 %%, -0.5°/m, 0.01 rad/√m, 0.01 m/√m)")
    ap.add_argument("--drift-seed", type=int, default=0,
                    help="with --drifted: the seed of the buildings' drift noise (the "
                    "simulated worlds keep their own)")
    ap.add_argument("--sonar-model", choices=("ideal", "realistic"), default="ideal",
                    help="with --drifted: the sonar the cases are simulated or emulated with "
                    "(docs/SONAR_PHYSICS.md; realistic: make compare's <name>-realistic logs "
                    "are the true-pose runs)")
    args = ap.parse_args(argv)
    if args.drifted:
        with tempfile.TemporaryDirectory(prefix="sonarmap-drift-") as tmp:
            drift_rows = drifted_comparison(args.keep if args.keep is not None else Path(tmp),
                                            args.tolerance, tuple(args.cases), args.config,
                                            walk=args.drift_model == "walk",
                                            drift_seed=args.drift_seed,
                                            sonar_model=args.sonar_model)
        print(drift_markdown(drift_rows))
        return 0

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
        table = summary(results)
        print(table, flush=True)
        if args.summary is not None:
            args.summary.write_text(table + "\n", encoding="utf-8")
        if args.figure is not None and results:
            figure(results, args.figure)
            print(f"figure: {args.figure}")
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
