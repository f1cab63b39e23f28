"""The specular and default methods' last pass recomputes the shadows of only the readings
the pass before it found stopped (with wall lines: stopped against the last pass's
surfaces): the same grids as recomputing every reading's."""

from __future__ import annotations

import numpy as np
import pytest
from specular_room import specular_scans

from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.forward import ForwardMapper
from pipeline.mapper.specular import SpecularMapper
from pipeline.mapper.synthetic import room_grid
from pipeline.methods import Method

GRIDS = ("free2", "arcs2", "hits2")


def _mapped(method: Method, threads: int = 1, lines_m: float = 0.0) -> SpecularMapper:
    config = MapperConfig(method=method, threads=threads, wall_line_half_length_m=lines_m)
    m = make_mapper(config, room_grid())
    assert isinstance(m, SpecularMapper)
    scans = specular_scans(120, 20.0)
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate_many(scans)
    return m


@pytest.mark.parametrize(("method", "lines_m"),
                         [(Method.FORWARD, 0.0), (Method.SPECULAR, 0.0), (Method.FORWARD, 0.3)])
def test_the_last_pass_keeps_its_bytes_with_the_shadows_reused(
    method: Method, lines_m: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    reused = _mapped(method, lines_m=lines_m)
    flags = np.unpackbits(np.concatenate(reused._shadowed))
    # Some readings are stopped by a silent wall, most are not (those are skipped).
    assert 0 < flags.sum() < 0.8 * flags.size
    reused._group_index = 0  # the last pass read these flags (its surfaces are pass 2's)
    n = 8 * reused._shadowed[0].size
    assert np.array_equal(reused._was_shadowed(n), np.unpackbits(reused._shadowed[0]) == 1)
    occupied = reused.snapshot().occupied  # the grids are complete once the map is taken
    want = {k: getattr(reused, k).copy() for k in GRIDS}
    want["occupied"] = occupied
    assert want["hits2"].sum() > 10 and want["occupied"].sum() > 100

    def everyone(self: SpecularMapper, readings: int) -> np.ndarray:
        return np.ones(readings, dtype=bool)  # every reading's shadows computed again

    monkeypatch.setattr(SpecularMapper, "_was_shadowed", everyone)
    again = _mapped(method, lines_m=lines_m)
    assert np.array_equal(want["occupied"], again.snapshot().occupied)
    for name in GRIDS:
        assert np.array_equal(want[name], getattr(again, name)), name
    assert again.counters.echoes_unattributed == reused.counters.echoes_unattributed


def test_a_group_that_differs_between_the_passes_is_refused() -> None:
    m = _mapped(Method.SPECULAR)
    m._group_index = 0
    n = 8 * m._shadowed[0].size
    assert m._was_shadowed(n).shape == (n,)
    with pytest.raises(RuntimeError, match="scan group 0 differs"):
        m._was_shadowed(n + 8)


def test_with_wall_lines_pass_3_flags_the_readings_pass_4s_surfaces_stop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Pass 3 judges passes against the estimated wall lines, pass 4 against the cells' own
    # normals: pass 3 flags the readings the latter stop, which pass 4 reuses.
    kept = _mapped(Method.FORWARD, lines_m=0.3)
    assert isinstance(kept, ForwardMapper) and kept._lines_on
    kept._group_index = 0
    n = 8 * kept._shadowed[0].size
    assert np.array_equal(kept._was_shadowed(n), np.unpackbits(kept._shadowed[0]) == 1)
    kept_flags = np.unpackbits(np.concatenate(kept._shadowed))
    kept_map = kept.snapshot().occupied

    def pass_threes_flags(self: SpecularMapper, readings: int) -> np.ndarray:
        return np.unpackbits(self._shadowed[self._group_index], count=readings).astype(bool)

    # Pass 3's own stops (against the lines) reused blindly: other readings, another map.
    monkeypatch.setattr(SpecularMapper, "later_surfaces", property(
        lambda self: None, lambda self, value: None), raising=False)
    monkeypatch.setattr(SpecularMapper, "_was_shadowed", pass_threes_flags)
    blind = _mapped(Method.FORWARD, lines_m=0.3)
    assert not np.array_equal(kept_flags, np.unpackbits(np.concatenate(blind._shadowed)))
    assert not np.array_equal(kept_map, blind.snapshot().occupied)
