"""Hypothesis properties of the pipeline: the configuration's dump → load round trip and
the reorder window's invariants."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from formats.contract import Batch, RangeBatch, make_range_batch
from formats.errors import ConfigError
from formats.options import CsvConfig, InputConfig, MountConfig, SensorsConfig
from pipeline.config import (
    Config,
    GridConfig,
    MapperConfig,
    PoseRefinementConfig,
    PoseSyncConfig,
    ScanConfig,
    dump_config,
    load_config,
)
from pipeline.stages.ingest import ordered_ranges

# Strings as TOML holds them: any Unicode scalar value (quotes, backslashes, controls,
# astral characters), no surrogates; no NUL (a configuration refuses it: no name holds one).
_text = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
                max_size=12)
_name = _text.filter(bool)


# A beam width: 0 (from the log) or in [0.5, 180) degrees.
_fov = st.one_of(st.just(0.0), st.floats(0.5, 179))


def _pos(hi: float = 1e3) -> st.SearchStrategy[float]:
    return st.floats(1e-6, hi, allow_nan=False)


@st.composite
def _configs(draw: st.DrawFn) -> Config:
    p_clamp_min = draw(st.floats(0.01, 0.49))
    mapper = MapperConfig(
        method=draw(st.sampled_from(["specular", "attribution", "andersone", "classic"])),
        sigma_d0=draw(_pos()),
        k_d=draw(st.floats(0, 10)),
        c_a=draw(_pos()),
        eps_max=draw(st.floats(0, 1)),
        match_distance=draw(_pos()),
        kappa_free=draw(st.floats(0, 10)),
        clear_on_max_range=draw(st.booleans()),
        feature_correction=draw(st.booleans()),
        n_particles=draw(st.integers(3, 10_000)),
        keep_fraction=draw(st.floats(0.001, 0.999)),
        protect_times=draw(st.integers(1, 1000)),
        split_guard=draw(st.booleans()),
        refit_positions=draw(st.sampled_from(["particle", "cell"])),
        sigma_min=draw(st.floats(0, 1)),
        p_free=draw(st.floats(0.01, 0.49)),
        p_clamp_min=p_clamp_min,
        p_clamp_max=draw(st.floats(0.51, 0.999)),
        p_occ=draw(st.floats(0.51, 0.999)),
        classic_p_occ=draw(st.floats(0.51, 0.999)),
        classic_thickness_cells=draw(_pos(100)),
        seed=draw(st.integers(0, 2**63 - 1)),
    )
    x0, y0 = draw(st.floats(-1e4, 1e4)), draw(st.floats(-1e4, 1e4))
    extent = draw(st.sampled_from([(), (x0, y0, x0 + 10.0, y0 + 5.0)]))
    grid = GridConfig(
        resolution=draw(st.floats(1e-3, 10)), extent=extent, margin=draw(st.floats(0, 10)),
        max_cells=draw(st.integers(1, 2**31 - 1)),
    )
    scans = ScanConfig(
        policy=draw(st.sampled_from(["time", "motion", "explicit"])),
        window_s=draw(st.floats(1e-6, 10)), max_travel_m=draw(_pos(10)), max_turn_deg=draw(_pos(90)),
    )
    pose_sync = PoseSyncConfig(
        max_pose_gap_s=draw(_pos(10)), time_offset_s=draw(st.floats(-10, 10))
    )
    csv = CsvConfig(
        layout=draw(st.sampled_from(["single", "set"])), ranges_file=draw(_name),
        delimiter=draw(_name), header=draw(st.booleans()),
        time_unit=draw(st.sampled_from(["s", "ms", "us", "ns"])),
        no_echo_value=draw(st.floats(-1, 100)),
    )
    inp = InputConfig(
        format=draw(_text), range_topics=tuple(draw(st.lists(_name, max_size=3))),
        pose_topic=draw(_text), base_frame=draw(_name), csv=csv,
    )
    names = draw(st.lists(_name, max_size=3, unique=True))
    mounts = tuple(
        MountConfig(
            name=n, x=draw(st.floats(-5, 5)), y=draw(st.floats(-5, 5)),
            yaw_deg=draw(st.floats(-180, 180)), fov_deg=draw(_fov),
        )
        for n in names
    )
    sensors = SensorsConfig(
        preset=draw(st.sampled_from(["", "pioneer-p3dx", "udacity-8sonar"])),
        fov_deg=draw(_fov), mounts=mounts,
    )
    refine = PoseRefinementConfig(
        enabled=draw(st.booleans()), match_submaps=draw(st.booleans()),
        submap_travel_m=draw(_pos(10)), max_echo_range_m=draw(_pos(10)),
        calibration_max_scale=draw(st.floats(0, 0.2)),
    )
    cfg = Config(
        mapper=mapper, grid=grid, scans=scans, pose_sync=pose_sync, pose_refinement=refine,
        input=inp, sensors=sensors,
    )
    try:  # drawn beyond a key's physical range (pipeline/config.py RANGES): not a config
        return cfg.validate()
    except ConfigError:
        assume(False)
        raise


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(cfg=_configs(), comments=st.booleans())
def test_config_dump_load_round_trip(cfg: Config, comments: bool) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "config.toml"
        path.write_text(dump_config(cfg, comments=comments), encoding="utf-8")
        loaded = load_config(path)
    assert loaded == cfg
    assert loaded.hash() == cfg.hash()


class _Batches:
    """The part of a LogReader that ``ordered_ranges`` reads: the range batches."""

    def __init__(self, batches: Sequence[RangeBatch]) -> None:
        self._batches = batches

    def batches(self, kinds: Sequence[str] = ("ranges",)) -> Iterator[Batch]:
        yield from self._batches


_stamp_lists = st.lists(
    st.lists(st.tuples(st.integers(0, 3), st.integers(0, 50)), max_size=20), max_size=12
)


@settings(max_examples=200, deadline=None)
@given(chunks=_stamp_lists, window=st.integers(0, 20))
def test_reorder_window_invariants(chunks: list[list[tuple[int, int]]], window: int) -> None:
    """Released readings are sorted by stamp; released + late + backwards = input; each
    released reading is one of the input's (stamps and sensors as a multiset)."""
    batches = []
    for k, rows in enumerate(chunks):
        sid = [s for s, _ in rows]
        t = [v for _, v in rows]
        batches.append(
            replace(
                make_range_batch(t, sid, 1.0, 0.5, 0.1, 5.0),
                range_m=np.arange(len(rows), dtype=np.float64) + 100.0 * k,  # row identity
            )
        )
    total = sum(len(rows) for rows in chunks)
    released: list[RangeBatch] = []
    late = backwards = 0
    for chunk in ordered_ranges(_Batches(batches), reorder_window_ns=window):  # type: ignore[arg-type]
        released.append(chunk.batch)
        late += chunk.late
        backwards += chunk.backwards
    out = RangeBatch.concat(released) if released else make_range_batch([], [], [], [], [], [])
    assert np.all(np.diff(out.t_ns) >= 0)
    assert len(out) + late + backwards == total
    given_rows = {(float(b.range_m[i]), int(b.t_ns[i])) for b in batches for i in range(len(b))}
    got = [(float(r), int(t)) for r, t in zip(out.range_m, out.t_ns, strict=True)]
    assert len(set(got)) == len(got) and set(got) <= given_rows


def test_config_strings_beyond_the_bmp_round_trip(tmp_path: Path) -> None:
    """Found by the property above: JSON-style surrogate-pair escapes are not TOML."""
    cfg = Config(input=InputConfig(base_frame="𐀀\x7f\"\\", pose_topic="/odom é"))
    path = tmp_path / "config.toml"
    path.write_text(dump_config(cfg), encoding="utf-8")
    assert load_config(path) == cfg
