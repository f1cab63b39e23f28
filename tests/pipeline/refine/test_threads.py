"""Parallel evaluations (pipeline.refine.threads): the same results in the same order as
one thread, so the calibration does not depend on how many cores run it."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from pipeline.refine import threads
from pipeline.refine.threads import parallel_map


def test_results_keep_the_items_order() -> None:
    items = list(range(23))
    assert parallel_map(lambda v: v * v, items) == [v * v for v in items]
    assert parallel_map(lambda v: v, []) == []


def test_the_calibration_is_the_same_on_one_thread(monkeypatch: pytest.MonkeyPatch,
                                                   sample_echoes: Callable[..., Any]) -> None:
    from pipeline.refine.calibration import calibrate

    track, far = sample_echoes("office", 5.0)
    near = far.take(np.flatnonzero(far.range_m <= 3.0))
    kwargs = dict(max_scale=0.05, max_bias=math.radians(3.0), res=0.05, sigma=0.1,
                  min_gain=0.01, far_echoes=far)
    many = calibrate(*track, near, **kwargs)
    monkeypatch.setattr(threads, "usable_cores", lambda: 1)
    one = calibrate(*track, near, **kwargs)
    np.testing.assert_equal(dataclasses.astuple(one), dataclasses.astuple(many))  # NaN = NaN
    assert many.scale_far_echoes and math.isfinite(many.scale_estimate)


def test_one_usable_core_evaluates_on_the_calling_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    import threading

    def where(_: int) -> int:
        return threading.get_ident()

    monkeypatch.setattr(threads, "usable_cores", lambda: 1)
    assert set(parallel_map(where, range(6))) == {threading.get_ident()}
    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    assert threading.get_ident() not in parallel_map(where, range(6))
