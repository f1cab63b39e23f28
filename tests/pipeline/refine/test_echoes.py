"""pipeline.refine.echoes: the echoes refinement works on."""

from __future__ import annotations

import numpy as np

from pipeline.refine import Echoes


def _echoes(ranges: list[float]) -> Echoes:
    n = len(ranges)
    return Echoes(t_ns=np.arange(n, dtype=np.int64), bx=np.zeros((n, 3)), by=np.zeros((n, 3)),
                  odo=np.zeros((n, 3)), sx=np.zeros(n), sy=np.zeros(n), axis=np.zeros(n),
                  half=np.full(n, 0.2), range_m=np.array(ranges))


def test_within_keeps_the_echoes_out_to_the_range_in_their_order() -> None:
    out = _echoes([4.0, 1.0, 3.0, 3.5, 0.5]).within(3.0)
    assert out.range_m.tolist() == [1.0, 3.0, 0.5]  # 3.0 itself is kept
    assert out.t_ns.tolist() == [1, 2, 4]
    assert out.bx.shape == (3, 3) and out.odo.shape == (3, 3)
    assert len(_echoes([4.0, 5.0]).within(3.0)) == 0


def test_mounts_number_the_sensors_by_position_and_axis() -> None:
    import dataclasses

    e = _echoes([1.0, 2.0, 1.5, 2.5, 0.8, 1.1])
    # two sonars at one position facing apart, a third beside them, interleaved in time
    e = dataclasses.replace(e, sx=np.array([0.1, 0.1, 0.2, 0.1, 0.1, 0.2]),
                            axis=np.array([0.0, 1.5, 0.0, 0.0, 1.5, 0.0]))
    ids = e.mounts()
    assert ids.dtype == np.int64 and ids.tolist() == [0, 1, 2, 0, 1, 2]
    assert _echoes([]).mounts().size == 0
