"""pipeline.refine.memo: a pure evaluation computed once per key."""

from __future__ import annotations

from pipeline.refine.memo import Memo


def test_a_key_is_computed_once_and_another_key_anew() -> None:
    calls: list[tuple[float, float]] = []
    memo: Memo[tuple[float, float], float] = Memo()

    def score(k: float, b: float) -> float:
        calls.append((k, b))
        return k + 10 * b

    assert memo.get((0.03, 0.1), lambda: score(0.03, 0.1)) == 0.03 + 1.0
    assert memo.get((0.03, 0.1), lambda: score(0.03, 0.1)) == 0.03 + 1.0
    assert calls == [(0.03, 0.1)]
    assert memo.get((0.0, 0.1), lambda: score(0.0, 0.1)) == 1.0
    assert calls == [(0.03, 0.1), (0.0, 0.1)]
