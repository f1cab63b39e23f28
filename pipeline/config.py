"""sonarmap's configuration, in one place.

One TOML file holds every parameter: the method's (``[mapper]``, ALGORITHM.md §1-5 and
§8), the grid, scan building (§6), pose sync, input selection (topics, CSV schema) and
sensor mounts. Each section is a frozen dataclass; each field's ``doc`` metadata is the
comment ``sonarmap config`` prints. Loading validates names, types and ranges and raises
:class:`~formats.errors.ConfigError` with one line naming the file and the key.

TOML is read by :func:`formats.toml_file.read_toml` (``tomllib``: no code is executed).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeAlias

from formats.errors import ConfigError
from formats.map_types import DEFAULT_MAX_CELLS
from formats.options import (
    FOV_MAX_DEG,
    FOV_MIN_DEG,
    MAX_NAME_CHARS,
    InputConfig,
    SensorsConfig,
    doc_field,
)
from formats.path_text import path_text_problem
from formats.presets import PRESETS
from formats.ranges import CELL_M, COORD_M, LIMIT_M, MOUNT_M, Range, above, open_range
from formats.storage.options import StorageConfig
from formats.toml_file import read_toml
from pipeline.methods import Method

# The pose refinement's choices its modules take as they are spelled here (one place).
TiltMode: TypeAlias = Literal["off", "fallback", "always"]  # the surfaces' patch models (calibration.py)


@dataclass(frozen=True)
class MapperConfig:
    """Parameters of the mapping method (ALGORITHM.md), with its documented defaults."""

    method: Method = doc_field(  # noqa: RUF009 - doc_field is dataclasses.field with a doc
        "mapping method: 'forward' (echo attribution with specular surfaces, the sonar's "
        "detection by incidence measured on the log, §11; the default), 'specular' (echo attribution with specular surfaces, §10), 'attribution' "
        "(echo attribution, §9), 'andersone' (the paper's, §1-5) or 'classic' (log-odds "
        "baseline, §8)",
        default=Method.FORWARD,
    )
    sigma_d0: float = doc_field("σ_d0, distance uncertainty at zero range, m (eq. 2)", default=0.01)
    k_d: float = doc_field("k_d, growth of distance uncertainty with range (eq. 2)", default=0.01)
    c_a: float = doc_field(
        "c_a in σ_a = d·tan(β/2)/c_a (eq. 3); 2 puts the 2σ bound on the cone edge",
        default=2.0,
    )
    eps_max: float = doc_field(
        "ε_max, m: readings with d ≥ r_max − ε_max count as 'no echo' (§1)", default=0.01
    )
    match_distance: float = doc_field(
        "a reading merges into the nearest feature closer than this, m (§2)", default=0.15
    )
    kappa_free: float = doc_field(
        "κ_free: a cone is free up to d − κ_free·σ_d(d) (§3)", default=2.0
    )
    clear_on_max_range: bool = doc_field(
        "let max-range readings clear their cone up to r_max (§3; paper: off)", default=False
    )
    feature_correction: bool = doc_field(
        "correct features with free-space scans (§4); off = the paper's ablation",
        default=True,
    )
    n_particles: int = doc_field("N, particles drawn per corrected feature (§4)", default=200)
    keep_fraction: float = doc_field(
        "a feature is refit when at least this fraction of particles survive (§4)",
        default=0.05,
    )
    protect_times: int = doc_field(
        "features measured at least this often are protected from deletion (§4)", default=3
    )
    split_guard: bool = doc_field(
        "a refit whose survivors' mean falls in a free cell of the scan counts as cleared "
        "(deleted unless protected) instead of refitting across the free cone; the paper "
        "does not cover this case (§4; false = eqs. 9-10 literally)",
        default=True,
    )
    refit_positions: Literal["particle", "cell"] = doc_field(
        "eqs. 9-10 refit from the survivors' own positions ('particle') or their cell "
        "centres ('cell', adds ~res²/12 of rounding variance at every refit) (§4)",
        default="particle",
    )
    sigma_min: float = doc_field(
        "σ_min, covariance floor, m; 0 = half a grid cell (§4)", default=0.0
    )
    p_free: float = doc_field("inverse sensor model value of a free observation (eq. 11)", default=0.35)
    p_clamp_min: float = doc_field("free layer clamp l_min = logit(p_clamp_min) (eq. 11)", default=0.12)
    p_clamp_max: float = doc_field("free layer clamp l_max = logit(p_clamp_max) (eq. 11)", default=0.97)
    p_occ: float = doc_field("probability of cells inside a feature's 2σ ellipse (eq. 12)", default=0.9)
    classic_p_occ: float = doc_field(
        "classic baseline: inverse sensor model value at the echo (§8)", default=0.7
    )
    classic_per_reading: bool = doc_field(
        "classic baseline: every reading updates the cells of its cone once (as OctoMap "
        "inserts each reading), instead of one update per cell per scan (§8)",
        default=True,
    )
    classic_thickness_cells: float = doc_field(
        "classic baseline: obstacle thickness w, in cells (§8)", default=1.0
    )
    attr_band_sigmas: float = doc_field(
        "attribution (§9): an echo's arc is d ± this many σ_d(d) (at least half a cell)",
        default=4.0,
    )
    attr_candidate_ratio: float = doc_field(
        "attribution (§9): an arc cell cannot have produced an echo when the log saw it "
        "free more than this many times as often as echo arcs cover it",
        default=2.0,
    )
    attr_dilution: float = doc_field(
        "attribution (§9): each of an echo's n candidate cells gets 1/n**attr_dilution "
        "(0 = a full hit each, 1 = an even split)",
        default=0.5,
    )
    attr_free_weight: float = doc_field(
        "attribution (§9): occupied when attributed weight > attr_free_weight·free count "
        "+ attr_threshold·median attributed weight",
        default=0.25,
    )
    attr_threshold: float = doc_field(
        "attribution (§9): the evidence floor, as a fraction of the log's median "
        "attributed weight per cell",
        default=0.35,
    )
    spec_critical_angle_deg: float = doc_field(
        "specular (§10 only; §11 measures the detection by incidence on the log): median "
        "critical angle of a surface, deg: a ray that meets a smooth surface farther than "
        "this from its normal is reflected away and returns no echo",
        default=25.0,
    )
    spec_critical_spread: float = doc_field(
        "specular (§10 only): spread of the critical angle across surfaces (σ of its "
        "logarithm), 1",
        default=0.35,
    )
    spec_normal_radius_m: float = doc_field(
        "specular (§10): radius over which the bearings of the echo arcs covering a cell are "
        "pooled into its surface normal, m",
        default=0.05,
    )
    wall_line_half_length_m: float = doc_field(
        "forward (§11): half length of the wall segment along which echoes from different "
        "places must agree on one tangent line (normal and offset) for its cells to be a wall "
        "in the surface-aware count pass, m; 0 = off (the cells' own arcs give the normals)",
        default=0.3,
    )
    spec_max_range_free: bool = doc_field(
        "specular (§10): readings with no echo are free evidence out to r_max, weighted like "
        "any ray by the chance that a surface there would have answered",
        default=True,
    )
    seed: int = doc_field("seed of the particle generator (runs are reproducible)", default=0)
    threads: int = doc_field(
        "threads the default method may use: 2 runs the paper's features on a second "
        "thread beside the rest of the run (results do not depend on it; not in config_hash)",
        default=2,
    )

    def sigma_floor(self, resolution: float) -> float:
        """σ_min in metres: the configured value, or half a cell when it is 0."""
        return self.sigma_min if self.sigma_min > 0 else 0.5 * resolution


@dataclass(frozen=True)
class GridConfig:
    """The map grid."""

    resolution: float = doc_field("cell size, m", default=0.05)
    extent: tuple[float, ...] = doc_field(
        "[xmin, ymin, xmax, ymax] in m; empty = from the poses plus max range",
        default=(),
    )
    margin: float = doc_field("extra border around an automatic extent, m", default=0.5)
    max_cells: int = doc_field(
        "refuse grids larger than this many cells (~32 bytes each while mapping: the "
        "default keeps a run under ~1.5 GB)",
        default=DEFAULT_MAX_CELLS,
    )


@dataclass(frozen=True)
class ScanConfig:
    """How readings are grouped into scans (ALGORITHM.md §6)."""

    policy: Literal["time", "motion", "explicit"] = doc_field(
        "'time' (window), 'motion' (travel/turn) or 'explicit' (scan id in the log)",
        default="time",
    )
    window_s: float = doc_field("time policy: scan length, s", default=0.2)
    max_travel_m: float = doc_field("motion policy: new scan after this travel, m", default=0.10)
    max_turn_deg: float = doc_field("motion policy: new scan after this turn, degrees", default=10.0)


@dataclass(frozen=True)
class PoseSyncConfig:
    """Interpolating the robot pose at each reading's stamp."""

    max_pose_gap_s: float = doc_field(
        "readings inside a pose gap longer than this are dropped, s; 0 = automatic: 3 x "
        "the log's median pose interval, within [0.5, 5] s (1 Hz odometry gets 2.7 s)",
        default=0.0,
    )
    time_offset_s: float = doc_field(
        "added to range stamps before lookup (sensor clock offset), s", default=0.0
    )


@dataclass(frozen=True)
class PoseRefinementConfig:
    """Correcting the odometry from the sonar data before mapping (``run --refine-poses``;
    pipeline/refine/)."""

    enabled: bool = doc_field("refine the poses before mapping (also: run --refine-poses)",
                         default=False)
    model: str = doc_field(
        "'graph': the one model (calibration, then the pose graph with the scale and heading "
        "bias as variables; pipeline/refine/refine.py); 'chain': the calibration, the walls' "
        "compass and local stretch corrections it replaces (pipeline/refine/chain.py, kept "
        "for comparison)", default="graph")
    max_echo_range_m: float = doc_field(
        "echoes farther than this are not matched (a sonar's range is reliable to a few "
        "metres), m", default=3.0)
    submap_travel_m: float = doc_field(
        "echoes are pooled into a submap per this much travel (odometry's drift over it "
        "stays below the field's σ), m", default=8.0)
    field_sigma_m: float = doc_field(
        "σ of the evidence field around each echo (the sonar's range and arc uncertainty; "
        "its cells are half of it), m", default=0.1)
    search_xy_m: float = doc_field(
        "consecutive submaps: matched within ± this of the odometry (its drift over a "
        "submap), m", default=0.5)
    search_yaw_deg: float = doc_field("consecutive submaps: matched within ± this yaw, degrees",
                                      default=8.0)
    loop_radius_m: float = doc_field(
        "loop closures: earlier submaps whose estimate lies within this distance are "
        "candidates (at least twice this travel back), m", default=8.0)
    loop_search_xy_m: float = doc_field(
        "loop closures: matched within ± this of the estimate (the drift left at a "
        "revisit), m", default=6.0)
    loop_search_yaw_deg: float = doc_field("loop closures: matched within ± this yaw, degrees",
                                           default=40.0)
    odometry_sigma_xy: float = doc_field("odometry translation noise σ, m per √m travelled",
                                         default=0.02)
    odometry_sigma_yaw_deg: float = doc_field("odometry heading noise σ, degrees per √m "
                                              "travelled", default=0.5)
    calibration_max_scale: float = doc_field(
        "the odometry's scale error is searched within ± this (fraction; 0: not searched)",
        default=0.05)
    calibration_max_bias_deg_per_m: float = doc_field(
        "the odometry's heading bias is searched within ± this, deg per m travelled",
        default=3.0)
    calibration_far_range_m: float = doc_field(
        "echoes out to this range also estimate the scale where they agree with the near "
        "ones (a specification test), m; 0: the near echoes only", default=5.0)

    @property
    def field_resolution_m(self) -> float:
        """The evidence field's cell, m: half its σ (the blur spans two cells)."""
        return self.field_sigma_m / 2

    @property
    def echo_reach_m(self) -> float:
        """The farthest echo refinement uses: those it matches, or the scale's far ones."""
        return max(self.max_echo_range_m, self.calibration_far_range_m)


# Keys that set how fast a run goes, never what it computes: left out of Config.hash.
SPEED_KEYS = (("mapper", "threads"),)
# Sections that say how the logs are reached, never what is computed from them: left out.
ACCESS_SECTIONS = ("storage",)


@dataclass(frozen=True)
class Config:
    """Everything a run needs besides the log itself."""

    mapper: MapperConfig = field(default_factory=MapperConfig)
    grid: GridConfig = field(default_factory=GridConfig)
    scans: ScanConfig = field(default_factory=ScanConfig)
    pose_sync: PoseSyncConfig = field(default_factory=PoseSyncConfig)
    pose_refinement: PoseRefinementConfig = field(default_factory=PoseRefinementConfig)
    input: InputConfig = field(default_factory=InputConfig)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)
    storage: StorageConfig = field(default_factory=StorageConfig)

    def validate(self) -> Config:
        """Check cross-field rules; raise ConfigError naming the key. Returns self."""
        _check_ranges(self)
        self.storage.check()
        for key in ("ranges_file", "poses_file", "sensors_file"):
            problem = path_text_problem(getattr(self.input.csv, key))
            if problem is not None:
                raise ConfigError(f"'input.csv.{key}' {problem}")
        return self

    def to_dict(self) -> dict[str, Any]:
        plain: dict[str, Any] = _to_plain(self)
        return plain

    def hash(self) -> str:
        """sha256 of the canonical JSON of the configuration (first 16 hex digits), without
        the keys that only set the speed (:data:`SPEED_KEYS`): no result depends on them."""
        plain = self.to_dict()
        for section, key in SPEED_KEYS:
            del plain[section][key]
        for section in ACCESS_SECTIONS:
            del plain[section]
        text = json.dumps(plain, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def replace(self, **sections: Any) -> Config:
        return dataclasses.replace(self, **sections)


# --------------------------------------------------------------------------- loading


def load_config(path: str | Path | None) -> Config:
    """Load and validate a TOML configuration; ``None`` gives the defaults."""
    if path is None:
        return Config().validate()
    p = Path(path)
    return config_from_dict(read_toml(p, "configuration"), source=p)


def config_from_dict(data: dict[str, Any], source: str | Path | None = None) -> Config:
    """Build a validated Config from plain data (as parsed from TOML)."""
    try:
        cfg: Config = _build(Config, data, "")
        return cfg.validate()
    except ConfigError as err:
        if source is not None and err.path is None:
            raise ConfigError(err.reason, source) from err
        raise


def _build(cls: type, data: Any, where: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"[{where or 'top level'}] must be a table, got {_tname(data)}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        known = ", ".join(sorted(names))
        raise ConfigError(f"unknown key '{_join(where, unknown[0])}' (known: {known})")
    kwargs = {k: _coerce(hints[k], v, _join(where, k)) for k, v in data.items()}
    return cls(**kwargs)


def _coerce(tp: Any, value: Any, key: str) -> Any:
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _build(tp, value, key)
    if origin is Literal:
        allowed = typing.get_args(tp)
        if value not in allowed:
            raise ConfigError(f"'{key}' must be one of {list(allowed)}, got {value!r}")
        return value
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        names = [m.value for m in tp]
        if not isinstance(value, str) or value not in names:
            raise ConfigError(f"'{key}' must be one of {names}, got {value!r}")
        return tp(value)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            raise ConfigError(f"'{key}' must be an array, got {_tname(value)}")
        item = args[0]
        if isinstance(item, type) and dataclasses.is_dataclass(item):
            return tuple(_build(item, v, f"{key}[{i}]") for i, v in enumerate(value))
        return tuple(_coerce(item, v, f"{key}[{i}]") for i, v in enumerate(value))
    if origin in (typing.Union, types.UnionType):
        raise ConfigError(f"'{key}': unsupported type")  # pragma: no cover - none declared
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"'{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"'{key}' must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"'{key}' must be a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"'{key}' must be a string, got {value!r}")
        return value
    raise ConfigError(f"'{key}': unsupported type {tp}")  # pragma: no cover


def _check_finite(obj: Any, where: str) -> None:
    """Every number of the configuration is finite: the range checks below compare with
    < and >, which inf passes and NaN makes meaningless (no key means inf or NaN). No
    string holds a NUL byte: no name sonarmap opens or matches can hold one."""
    for f in dataclasses.fields(obj):
        v, key = getattr(obj, f.name), _join(where, f.name)
        items = v if isinstance(v, tuple) else (v,)
        for i, item in enumerate(items):
            k = f"{key}[{i}]" if isinstance(v, tuple) else key
            if dataclasses.is_dataclass(item) and not isinstance(item, type):
                _check_finite(item, k)
            elif isinstance(item, float) and not math.isfinite(item):
                raise ConfigError(f"'{k}' must be a finite number, got {item!r}")
            elif isinstance(item, str) and "\x00" in item:
                raise ConfigError(f"'{k}' must not contain a NUL byte, got {item!r}")


# --------------------------------------------------------------------------- ranges

_PROB = open_range(0, 1)
_INT32 = 2**31 - 1
# The physical range of every number of the configuration, by key ('sensors.mounts.x'
# covers every mount): checked by _check_ranges as the file is loaded, named in the error.
# Integer ranges are what the quantity can mean; real ranges what a sonar, a robot and
# int64 nanosecond stamps (±292 years) can hold. A numeric key missing here is refused
# by tests/pipeline/test_config.py.
RANGES: dict[str, Range] = {
    "storage.block_size_mib": Range(0.0625, 1024, "MiB"),
    "storage.cache_blocks": Range(1, 1000),
    "storage.timeout_s": above(0, 3600, "s"),
    "storage.retries": Range(0, 1000),
    "storage.backoff_s": Range(0, 3600, "s"),
    "mapper.sigma_d0": above(0, 1, "m"),
    "mapper.k_d": Range(0, 1),
    "mapper.c_a": above(0, 100),
    "mapper.eps_max": Range(0, 10, "m"),
    "mapper.match_distance": above(0, 10, "m"),
    "mapper.kappa_free": Range(0, 10),
    "mapper.n_particles": Range(3, 100_000),
    "mapper.keep_fraction": _PROB,
    "mapper.protect_times": Range(1, _INT32),
    "mapper.sigma_min": Range(0, 1, "m"),
    "mapper.p_free": open_range(0, 0.5),
    "mapper.p_clamp_min": open_range(0, 0.5),
    "mapper.p_clamp_max": open_range(0.5, 1),
    "mapper.p_occ": open_range(0.5, 1),
    "mapper.classic_p_occ": open_range(0.5, 1),
    "mapper.classic_thickness_cells": above(0, 1000, "cells"),
    "mapper.attr_band_sigmas": above(0, 100),
    "mapper.attr_candidate_ratio": above(0, 1e6),
    "mapper.attr_dilution": Range(0, 1),
    "mapper.attr_free_weight": Range(0, 1e6),
    "mapper.attr_threshold": Range(0, 1e6),
    "mapper.spec_critical_angle_deg": Range(0.1, 90),
    "mapper.spec_critical_spread": Range(0.001, 5),
    "mapper.spec_normal_radius_m": Range(0, 10),
    "mapper.wall_line_half_length_m": Range(0, 10),
    "mapper.seed": Range(0, 2**63, hi_open=True),
    "mapper.threads": Range(1, 2),
    "grid.resolution": CELL_M,
    "grid.extent": COORD_M,
    "grid.margin": Range(0, 1e4, "m"),
    "grid.max_cells": Range(1, _INT32),
    "scans.window_s": Range(1e-6, 3600, "s"),
    "scans.max_travel_m": above(0, 1e4, "m"),
    "scans.max_turn_deg": above(0, 360, "deg"),
    "pose_sync.max_pose_gap_s": Range(0, 86_400, "s", zero="automatic"),
    "pose_sync.time_offset_s": Range(-4e9, 4e9, "s"),
    "input.max_file_gap_s": Range(0, 86_400 * 365, "s"),
    "input.csv.no_echo_value": Range(-1e9, 1e9, zero="none"),
    "sensors.fov_deg": Range(FOV_MIN_DEG, FOV_MAX_DEG, "deg", hi_open=True, zero="from the log"),
    "sensors.min_range": dataclasses.replace(LIMIT_M, zero="from the log"),
    "sensors.max_range": dataclasses.replace(LIMIT_M, zero="from the log"),
    "sensors.mounts.x": MOUNT_M,
    "sensors.mounts.y": MOUNT_M,
    "sensors.mounts.yaw_deg": Range(-360, 360, "deg"),
    "sensors.mounts.fov_deg": Range(FOV_MIN_DEG, FOV_MAX_DEG, "deg", hi_open=True,
                                    zero="from the log"),
    "sensors.mounts.min_range": dataclasses.replace(LIMIT_M, zero="from the log"),
    "sensors.mounts.max_range": dataclasses.replace(LIMIT_M, zero="from the log"),
    # [pose_refinement]: generous outer limits (its own rules follow in _check_ranges).
    **{f"pose_refinement.{k}": r for k, r in {
        "submap_travel_m": above(0, 1e4, "m"), "max_echo_range_m": above(0, 1000, "m"),
        "field_sigma_m": Range(2e-3, 100, "m"),
        "search_xy_m": above(0, 100, "m"), "search_yaw_deg": above(0, 180, "deg"),
        "loop_radius_m": above(0, 1e4, "m"),
        "loop_search_xy_m": above(0, 100, "m"), "loop_search_yaw_deg": above(0, 180, "deg"),
        "odometry_sigma_xy": above(0, 10, "m/√m"), "odometry_sigma_yaw_deg": above(0, 90),
        "calibration_max_scale": Range(0, 0.5, hi_open=True),
        "calibration_far_range_m": Range(0, 1000, "m", zero="off"),
        "calibration_max_bias_deg_per_m": above(0, 45, "deg/m"),
    }.items()},
}


def numeric_keys(obj: Any, where: str = "") -> list[tuple[str, str, Any]]:
    """(key, RANGES key, value) of every number in a configuration section, nested tables
    and arrays included (``sensors.mounts[1].x`` → ``sensors.mounts.x``)."""
    out: list[tuple[str, str, Any]] = []
    for f in dataclasses.fields(obj):
        v, key = getattr(obj, f.name), _join(where, f.name)
        generic = key if not where else _join(_generic(where), f.name)
        items = list(enumerate(v)) if isinstance(v, tuple) else [(None, v)]
        for i, item in items:
            k = key if i is None else f"{key}[{i}]"
            if dataclasses.is_dataclass(item) and not isinstance(item, type):
                out += numeric_keys(item, k)
            elif isinstance(item, int | float) and not isinstance(item, bool):
                out.append((k, generic, item))
    return out


def _generic(key: str) -> str:
    """``sensors.mounts[1]`` → ``sensors.mounts``."""
    return ".".join(part.split("[")[0] for part in key.split("."))


def _check_ranges(cfg: Config) -> None:
    _check_finite(cfg, "")
    m, g = cfg.mapper, cfg.grid

    def need(ok: bool, key: str, rule: str, value: Any) -> None:
        if not ok:
            raise ConfigError(f"'{key}' {rule}, got {value!r}")

    need(m.threads in (1, 2), "mapper.threads", "must be 1 or 2", m.threads)
    if g.extent:
        need(len(g.extent) == 4, "grid.extent", "must be [xmin, ymin, xmax, ymax]", g.extent)
        x0, y0, x1, y1 = g.extent
        need(x0 < x1 and y0 < y1, "grid.extent", "must have xmin < xmax and ymin < ymax", g.extent)
    pr = cfg.pose_refinement
    for key in ("submap_travel_m", "max_echo_range_m", "field_sigma_m",
                "search_xy_m", "search_yaw_deg", "loop_radius_m", "loop_search_xy_m",
                "loop_search_yaw_deg", "odometry_sigma_xy", "odometry_sigma_yaw_deg"):
        v = getattr(pr, key)
        need(math.isfinite(v) and v > 0, f"pose_refinement.{key}", "must be > 0", v)
    need(0 <= pr.calibration_max_scale < 0.5, "pose_refinement.calibration_max_scale",
         "must be in [0, 0.5)", pr.calibration_max_scale)
    need(math.isfinite(pr.calibration_far_range_m) and pr.calibration_far_range_m >= 0,
         "pose_refinement.calibration_far_range_m", "must be >= 0 (0 = off)",
         pr.calibration_far_range_m)
    need(0 < pr.calibration_max_bias_deg_per_m <= 45,
         "pose_refinement.calibration_max_bias_deg_per_m", "must be in (0, 45]",
         pr.calibration_max_bias_deg_per_m)
    need(pr.model in ("graph", "chain"), "pose_refinement.model", "must be 'graph' or 'chain'",
         pr.model)
    sc = cfg.sensors
    _check_limits("sensors", sc.min_range, sc.max_range)
    for i, mt in enumerate(sc.mounts):
        key = f"sensors.mounts[{i}]"
        need(bool(mt.name), f"{key}.name", "must be set", mt.name)
        need(len(mt.name) <= MAX_NAME_CHARS, f"{key}.name",
             f"must be at most {MAX_NAME_CHARS} characters", f"{mt.name[:40]}...")
        _check_limits(key, mt.min_range, mt.max_range)
    names = [mt.name for mt in sc.mounts]
    dup = sorted({n for n in names if names.count(n) > 1})
    need(not dup, "sensors.mounts", "has duplicate names", dup)
    if sc.preset:
        need(sc.preset in PRESETS, "sensors.preset", f"must be one of {sorted(PRESETS)}", sc.preset)
    csv = cfg.input.csv
    need(bool(csv.delimiter), "input.csv.delimiter", "must not be empty", csv.delimiter)
    for key, generic, value in numeric_keys(cfg):
        rng = RANGES.get(generic)
        if rng is None:  # pragma: no cover - tests/pipeline/test_config.py keeps RANGES whole
            raise ConfigError(f"'{key}' has no declared range (a defect of sonarmap)")
        if not rng.holds(value):
            raise ConfigError(f"'{key}' {rng.rule()}, got {value!r}")


def _check_limits(key: str, lo: float, hi: float) -> None:
    if lo < 0 or hi < 0:
        raise ConfigError(f"'{key}.min_range/max_range' must be >= 0, got {(lo, hi)!r}")
    if lo > 0 and hi > 0 and not lo < hi:
        raise ConfigError(f"'{key}.min_range' must be < max_range, got {(lo, hi)!r}")


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _tname(v: Any) -> str:
    return type(v).__name__


def _to_plain(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple):
        return [_to_plain(v) for v in obj]
    if isinstance(obj, float) and math.isnan(obj):
        return "nan"
    return obj


# --------------------------------------------------------------------------- dumping


def dump_config(cfg: Config, *, comments: bool = True) -> str:
    """The configuration as a TOML document, each key preceded by its doc comment."""
    lines: list[str] = []
    if comments:
        lines += [
            "# sonarmap configuration. Every key is optional; shown are the values in effect.",
            "# Load with: sonarmap run LOG -o OUT --config this.toml",
            "",
        ]
    _dump_table(cfg, "", lines, comments)
    return "\n".join(lines).rstrip() + "\n"


def _dump_table(obj: Any, prefix: str, lines: list[str], comments: bool) -> None:
    scalars = []
    tables = []
    arrays = []
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            tables.append((f, v))
        elif isinstance(v, tuple) and v and dataclasses.is_dataclass(v[0]):
            arrays.append((f, v))
        else:
            scalars.append((f, v))
    if prefix and (scalars or not tables):
        lines.append(f"[{prefix}]")
    for f, v in scalars:
        if comments and f.metadata.get("doc"):
            lines.append(f"# {f.metadata['doc']}")
        lines.append(f"{f.name} = {_toml_value(v)}")
    if prefix and scalars:
        lines.append("")
    for f, v in tables:
        _dump_table(v, _join(prefix, f.name), lines, comments)
    for f, items in arrays:
        for item in items:
            lines.append(f"[[{_join(prefix, f.name)}]]")
            for g in dataclasses.fields(item):
                lines.append(f"{g.name} = {_toml_value(getattr(item, g.name))}")
            lines.append("")


_TOML_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped, every
    other character as itself (TOML's \\u escapes take no surrogate halves, so characters
    beyond the BMP cannot be escaped the way JSON does)."""
    out = []
    for ch in text:
        if ch in _TOML_ESCAPES:
            out.append(_TOML_ESCAPES[ch])
        elif ch < " " or ch == "\x7f":
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")  # pragma: no cover
