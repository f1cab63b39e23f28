"""trajectory.png (formats.writers.trajectory_png): both tracks drawn, deterministic."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from formats.writers.trajectory_png import ODOMETRY, REFINED, trajectory_png_bytes


def test_both_tracks_are_drawn_and_bytes_repeat() -> None:
    t = np.linspace(0, 5, 50)
    odo = np.column_stack([t, 0.2 * t])
    ref = np.column_stack([t, np.zeros_like(t)])
    png = trajectory_png_bytes(odo, ref, "room")
    assert png == trajectory_png_bytes(odo, ref, "room")
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    colours = {tuple(c) for c in img.reshape(-1, 3).tolist()}
    assert ODOMETRY in colours and REFINED in colours
    # The refined track (y = 0) is a horizontal line: one row holds most of its pixels.
    rows = np.nonzero((img == REFINED).all(axis=2))[0]
    assert np.bincount(rows).max() > 0.5 * img.shape[1]
