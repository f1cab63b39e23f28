"""nav2 map_server maps: exact files written, and loaded back with map_server's rules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from formats.errors import FormatError
from formats.map_types import GridSpec
from formats.writers.nav2_map import load_nav2_map, write_nav2_map

GRID = GridSpec(origin_x=-1.5, origin_y=2.25, resolution=0.05, width=4, height=3)


def _pgm_pixels(path: Path) -> np.ndarray:
    data = path.read_bytes()
    header, _, _ = data.partition(b"\n255\n")
    w, h = (int(v) for v in header.split()[1:3])
    return np.frombuffer(data[len(header) + 5 :], dtype=np.uint8).reshape(h, w)


def _write_yaml(path: Path, image: str, **overrides: object) -> Path:
    doc: dict[str, object] = {
        "image": image,
        "mode": "trinary",
        "resolution": 0.1,
        "origin": [0.0, 0.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    doc.update(overrides)
    doc = {k: v for k, v in doc.items() if v is not None}
    path.write_text(yaml.safe_dump(doc))
    return path


def test_yaml_keys_and_values_exact(tmp_path: Path) -> None:
    write_nav2_map(tmp_path / "map.yaml", np.full(GRID.shape, np.nan, np.float32), GRID)
    text = (tmp_path / "map.yaml").read_text()
    assert text == (
        "image: map.pgm\n"
        "mode: trinary\n"
        "resolution: 0.05\n"
        "origin: [-1.5, 2.25, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    assert yaml.safe_load(text) == {
        "image": "map.pgm",
        "mode": "trinary",
        "resolution": 0.05,
        "origin": [-1.5, 2.25, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }


def test_pgm_header_pixels_and_row_flip(tmp_path: Path) -> None:
    prob = np.full(GRID.shape, 0.0, dtype=np.float32)
    prob[0, 1] = 0.9  # min-y row: must be the LAST image row
    prob[2, 3] = np.nan  # max-y row: the FIRST image row
    prob[1, 0] = 0.5  # between thresholds: unknown
    write_nav2_map(tmp_path / "m.yaml", prob, GRID)
    data = (tmp_path / "m.pgm").read_bytes()
    assert data.startswith(b"P5\n4 3\n255\n")
    assert len(data) == len(b"P5\n4 3\n255\n") + 12
    px = _pgm_pixels(tmp_path / "m.pgm")
    assert px.tolist() == [
        [254, 254, 254, 205],
        [205, 254, 254, 254],
        [254, 0, 254, 254],
    ]


def test_threshold_rule_is_strict(tmp_path: Path) -> None:
    grid = GridSpec(0.0, 0.0, 1.0, 4, 1)
    # 0.5 and 0.25 are exact in float32: equality is the boundary case of both rules.
    prob = np.array([[0.5, 0.50001, 0.25, 0.24999]], dtype=np.float32)
    write_nav2_map(tmp_path / "t.yaml", prob, grid, occupied_thresh=0.5, free_thresh=0.25)
    assert _pgm_pixels(tmp_path / "t.pgm").tolist() == [[205, 0, 205, 254]]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_round_trip_random_grids(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 40, size=2)
    grid = GridSpec(float(rng.normal()), float(rng.normal()), 0.1, int(w), int(h))
    prob = rng.random((h, w)).astype(np.float32)
    prob[rng.random((h, w)) < 0.2] = np.nan
    write_nav2_map(tmp_path / "r.yaml", prob, grid)
    m = load_nav2_map(tmp_path / "r.yaml")
    expected = np.where(prob > 0.65, 1, np.where(prob < 0.196, 0, -1))
    np.testing.assert_array_equal(m.classes, expected)
    assert m.classes.dtype == np.int8
    assert m.grid == grid
    assert m.probability.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(m.probability), expected == -1)
    np.testing.assert_array_equal(m.occupancy, np.where(expected == 1, 100, expected))


def test_single_occupied_cell_at_min_y_is_last_pgm_row(tmp_path: Path) -> None:
    grid = GridSpec(0.0, 0.0, 0.5, 5, 6)
    prob = np.zeros(grid.shape, dtype=np.float32)
    prob[0, 2] = 1.0
    write_nav2_map(tmp_path / "one.yaml", prob, grid)
    px = _pgm_pixels(tmp_path / "one.pgm")
    assert np.argwhere(px == 0).tolist() == [[5, 2]]
    m = load_nav2_map(tmp_path / "one.yaml")
    assert np.argwhere(m.classes == 1).tolist() == [[0, 2]]


def test_custom_thresholds_still_load_as_written(tmp_path: Path) -> None:
    grid = GridSpec(0.0, 0.0, 1.0, 3, 1)
    prob = np.array([[0.3, 0.55, 0.9]], dtype=np.float32)
    write_nav2_map(tmp_path / "c.yaml", prob, grid, occupied_thresh=0.5, free_thresh=0.4)
    assert load_nav2_map(tmp_path / "c.yaml").classes.tolist() == [[0, 1, 1]]


def test_bytes_are_deterministic(tmp_path: Path) -> None:
    prob = np.random.default_rng(5).random(GRID.shape).astype(np.float32)
    (tmp_path / "a").mkdir()
    write_nav2_map(tmp_path / "a" / "m.yaml", prob, GRID)
    write_nav2_map(tmp_path / "m.yaml", prob, GRID)
    assert (tmp_path / "a" / "m.pgm").read_bytes() == (tmp_path / "m.pgm").read_bytes()
    assert (tmp_path / "a" / "m.yaml").read_bytes() == (tmp_path / "m.yaml").read_bytes()


def test_odd_stem_is_quoted(tmp_path: Path) -> None:
    write_nav2_map(tmp_path / "my map: #1.yaml", np.zeros(GRID.shape, np.float32), GRID)
    doc = yaml.safe_load((tmp_path / "my map: #1.yaml").read_text())
    assert doc["image"] == "my map: #1.pgm"
    assert load_nav2_map(tmp_path / "my map: #1.yaml").classes.shape == (3, 4)


def test_shape_mismatch_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"shape \(2, 2\), grid is \(3, 4\)"):
        write_nav2_map(tmp_path / "x.yaml", np.zeros((2, 2), np.float32), GRID)


def test_load_p2_ascii_with_comment_and_negate(tmp_path: Path) -> None:
    (tmp_path / "a.pgm").write_bytes(b"P2\n# made by hand\n3 2\n255\n0 254 205\n255 10 128\n")
    _write_yaml(tmp_path / "a.yaml", "a.pgm")
    m = load_nav2_map(tmp_path / "a.yaml")
    # image row 1 (bottom) is grid row 0
    assert m.classes.tolist() == [[0, 1, -1], [1, 0, -1]]
    assert m.probability[1, 0] == pytest.approx(1.0)
    assert m.probability[1, 1] == pytest.approx(1 / 255)
    _write_yaml(tmp_path / "n.yaml", "a.pgm", negate=1)
    n = load_nav2_map(tmp_path / "n.yaml")
    # negate: p = value/255, so 205 (0.80) reads as occupied
    assert n.classes.tolist() == [[1, 0, -1], [0, 1, 1]]


def test_load_scale_mode_png_with_alpha(tmp_path: Path) -> None:
    la = np.array([[[0, 255], [255, 255], [128, 255], [128, 0]]], dtype=np.uint8)
    Image.fromarray(la, mode="LA").save(tmp_path / "s.png")
    _write_yaml(tmp_path / "s.yaml", "s.png", mode="scale", free_thresh=0.25)
    m = load_nav2_map(tmp_path / "s.yaml")
    occ = 1 - 128 / 255
    assert m.occupancy.tolist() == [[100, 0, round((occ - 0.25) / 0.4 * 100), -1]]
    assert m.classes.tolist() == [[1, 0, -1, -1]]
    assert m.probability[0, 2] == pytest.approx(occ)
    assert np.isnan(m.probability[0, 3])


def test_load_trinary_rgb_averages_channels(tmp_path: Path) -> None:
    rgb = np.array([[[255, 255, 255], [0, 0, 30], [255, 0, 0]]], dtype=np.uint8)
    Image.fromarray(rgb, mode="RGB").save(tmp_path / "c.png")
    _write_yaml(tmp_path / "c.yaml", "c.png")
    # p = 1 - mean/255: 0 free, 0.96 occupied, 0.667 occupied
    assert load_nav2_map(tmp_path / "c.yaml").classes.tolist() == [[0, 1, 1]]


def test_load_raw_mode(tmp_path: Path) -> None:
    (tmp_path / "r.pgm").write_bytes(b"P5\n3 1\n255\n" + bytes([0, 100, 200]))
    _write_yaml(tmp_path / "r.yaml", "r.pgm", mode="raw")
    m = load_nav2_map(tmp_path / "r.yaml")
    assert m.occupancy.tolist() == [[0, 100, -1]]
    assert m.classes.tolist() == [[0, 1, -1]]


def test_mode_defaults_to_trinary_and_absolute_image(tmp_path: Path) -> None:
    write_nav2_map(tmp_path / "m.yaml", np.ones(GRID.shape, np.float32), GRID)
    sub = tmp_path / "sub"
    sub.mkdir()
    _write_yaml(sub / "abs.yaml", str(tmp_path / "m.pgm"), mode=None)
    assert (load_nav2_map(sub / "abs.yaml").classes == 1).all()


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"image": None}, "has no 'image'"),
        ({"resolution": "fine"}, "'resolution' is not a number"),
        ({"resolution": 0}, r"'resolution' must be in \[0.001, 100\] m, got 0"),
        ({"origin": [0, 0]}, "'origin' must be a list of 3 numbers"),
        ({"origin": [0, 0, 0.5]}, "yaw 0.5 rad is not supported"),
        ({"mode": "fancy"}, "'mode' must be trinary, scale or raw"),
        ({"negate": None}, "'negate' must be 0 or 1"),
        ({"free_thresh": None}, "has no 'free_thresh'"),
        ({"image": "missing.pgm"}, "missing.pgm: map image not found"),
    ],
)
def test_bad_yaml_is_format_error(
    tmp_path: Path, overrides: dict[str, object], message: str
) -> None:
    (tmp_path / "ok.pgm").write_bytes(b"P5\n1 1\n255\n\x00")
    overrides = {"image": "ok.pgm", **overrides} if "image" not in overrides else overrides
    path = _write_yaml(tmp_path / "bad.yaml", **overrides)  # type: ignore[arg-type]
    with pytest.raises(FormatError, match=message) as info:
        load_nav2_map(path)
    assert str(tmp_path) in str(info.value)


def test_broken_files_are_format_errors(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"nope\.yaml: map YAML not found"):
        load_nav2_map(tmp_path / "nope.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(FormatError, match=r"list\.yaml: map YAML is not a mapping"):
        load_nav2_map(tmp_path / "list.yaml")
    (tmp_path / "syntax.yaml").write_text("image: [unclosed\n")
    with pytest.raises(FormatError, match=r"syntax\.yaml: not a readable map YAML"):
        load_nav2_map(tmp_path / "syntax.yaml")
    (tmp_path / "short.pgm").write_bytes(b"P5\n4 4\n255\n\x00\x00")
    _write_yaml(tmp_path / "short.yaml", "short.pgm")
    with pytest.raises(FormatError, match=r"short.pgm: PGM raster truncated: 2 bytes, expected 16"):
        load_nav2_map(tmp_path / "short.yaml")
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    _write_yaml(tmp_path / "junk.yaml", "junk.png")
    with pytest.raises(FormatError, match=r"junk\.png: not a readable image"):
        load_nav2_map(tmp_path / "junk.yaml")


def test_load_boundary_values(tmp_path: Path) -> None:
    """Thresholds compare strictly, at their exact values; maxval 256 means 16-bit samples;
    a zero width is refused; thresholds above 1 make nothing occupied."""
    # occ = 1 - v/1000: v = 750 -> 0.25 (= free_thresh), v = 250 -> 0.75 (= occupied_thresh)
    (tmp_path / "edge.pgm").write_bytes(b"P2\n4 1\n1000\n750 749 250 251\n")
    _write_yaml(tmp_path / "edge.yaml", "edge.pgm", free_thresh=0.25, occupied_thresh=0.75)
    edge = load_nav2_map(tmp_path / "edge.yaml")
    assert edge.classes.tolist() == [[-1, -1, -1, -1]]  # none strictly beyond a threshold
    assert edge.occupancy.tolist() == [[-1, -1, -1, -1]]
    (tmp_path / "past.pgm").write_bytes(b"P2\n2 1\n1000\n751 249\n")
    _write_yaml(tmp_path / "past.yaml", "past.pgm", free_thresh=0.25, occupied_thresh=0.75)
    assert load_nav2_map(tmp_path / "past.yaml").classes.tolist() == [[0, 1]]

    # maxval 256: two bytes per sample, big-endian; 256 is white (free), 0 black (occupied)
    (tmp_path / "wide.pgm").write_bytes(b"P5\n3 1\n256\n" + np.array([0, 256, 128], ">u2").tobytes())
    _write_yaml(tmp_path / "wide.yaml", "wide.pgm")
    wide = load_nav2_map(tmp_path / "wide.yaml")
    assert wide.classes.tolist() == [[1, 0, -1]]
    assert wide.probability[0, 2] != wide.probability[0, 2]  # 0.5: between, unknown (NaN)

    (tmp_path / "zero.pgm").write_bytes(b"P5\n0 3\n255\n")
    _write_yaml(tmp_path / "zero.yaml", "zero.pgm")
    with pytest.raises(FormatError, match=r"zero\.pgm: bad PGM header: 0x3, maxval 255"):
        load_nav2_map(tmp_path / "zero.yaml")

    (tmp_path / "hi.pgm").write_bytes(b"P2\n2 1\n255\n0 255\n")
    _write_yaml(tmp_path / "hi.yaml", "hi.pgm", occupied_thresh=1.5, free_thresh=1.2)
    hi = load_nav2_map(tmp_path / "hi.yaml")
    assert hi.classes.tolist() == [[0, 0]]  # black (occ 1.0) is below 1.2: free, not occupied


def test_pgm_value_above_maxval_is_named(tmp_path: Path) -> None:
    (tmp_path / "over.pgm").write_bytes(b"P2\n2 1\n100\n0 101\n")
    _write_yaml(tmp_path / "over.yaml", "over.pgm")
    with pytest.raises(FormatError, match=r"over\.pgm: PGM value above maxval 100$"):
        load_nav2_map(tmp_path / "over.yaml")


def test_non_finite_grid_numbers_are_refused_by_name(tmp_path: Path) -> None:
    bad = GridSpec(origin_x=float("nan"), origin_y=0.0, resolution=0.05, width=4, height=3)
    with pytest.raises(ValueError, match=r"^origin_x must be finite, got nan$"):
        write_nav2_map(tmp_path / "m.yaml", np.zeros(GRID.shape, np.float32), bad)
    assert not (tmp_path / "m.yaml").exists()


def test_32_bit_integer_image_reads_as_16_bit_grey(tmp_path: Path) -> None:
    # Mode "I" (32-bit samples, here a TIFF) is scaled by 65535 like 16-bit PNGs: 32768 is
    # mid-grey (unknown in trinary), not clipped to white by an 8-bit conversion.
    Image.fromarray(np.array([[0, 32768, 65535]], dtype=np.int32), mode="I").save(tmp_path / "i.tif")
    with Image.open(tmp_path / "i.tif") as img:
        assert img.mode == "I"
    _write_yaml(tmp_path / "i.yaml", "i.tif")
    assert load_nav2_map(tmp_path / "i.yaml").classes.tolist() == [[1, -1, 0]]


def test_pgm_with_maxval_1_is_a_black_and_white_map(tmp_path: Path) -> None:
    (tmp_path / "bw.pgm").write_bytes(b"P2\n2 1\n1\n0 1\n")
    _write_yaml(tmp_path / "bw.yaml", "bw.pgm")
    assert load_nav2_map(tmp_path / "bw.yaml").classes.tolist() == [[1, 0]]
