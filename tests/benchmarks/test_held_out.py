"""benchmarks.held_out: a sample world turned about its centre, waypoints and all."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from benchmarks.held_out import MODELS, WORLDS, world_file


def test_a_world_named_alone_is_the_sample_world(tmp_path: Path) -> None:
    assert world_file("skew", tmp_path) == WORLDS / "skew.toml"
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SystemExit, match="no world"):
        world_file("nowhere@10", tmp_path)


def test_a_turned_world_keeps_its_shape_and_turns_its_path(tmp_path: Path) -> None:
    path = world_file("rooms@90", tmp_path)
    src = tomllib.loads((WORLDS / "rooms.toml").read_text(encoding="utf-8"))
    turned = tomllib.loads(path.read_text(encoding="utf-8"))
    assert turned["name"] == "rooms-90"
    (x0, y0, x1, y1), (cx, cy) = src["bounds"], (12.0, 5.5)
    # 90° about the centre: (x, y) → (cx − (y − cy), cy + (x − cx))
    first = src["segment"][0]["from"]
    assert turned["segment"][0]["from"] == pytest.approx([cx - (first[1] - cy), cy + (first[0] - cx)])
    assert len(turned["segment"]) == len(src["segment"])
    assert turned["circle"][0]["radius"] == src["circle"][0]["radius"]
    b = turned["bounds"]  # the turned outline (24 × 11 m → 11 × 24 m) with 1 m to spare
    assert b[2] - b[0] == pytest.approx(y1 - y0 + 2, abs=0.01)
    assert b[3] - b[1] == pytest.approx(x1 - x0 + 2, abs=0.01)
    rows = path.with_name("rooms-90.waypoints.csv").read_text(encoding="utf-8").splitlines()
    assert rows[0] == "x,y" and rows[1] == f"{cx - (5.5 - cy)},{cy + (1.0 - cx)}"
    assert math.isclose(float(rows[1].split(",")[1]), -5.5)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_drift_model_s_label_states_its_values(name: str) -> None:
    label, scale, bias, noise_xy, noise_yaw = MODELS[name]
    words = [w.strip() for w in label.split(",")]
    assert words[0] == f"{scale * 100:+g} %"
    assert words[1] == f"{bias:+g}°/m"
    noise = " ".join(words[2:])
    assert (f"{noise_xy:g} m/√m" in noise) == (noise_xy > 0)
    assert (f"{noise_yaw:g} rad/√rad" in noise) == (noise_yaw > 0)
