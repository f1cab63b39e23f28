"""pipeline.cores: the cores a process may use, as its affinity says."""

from __future__ import annotations

import pytest

from pipeline import cores
from pipeline.cores import usable_cores


def test_the_affinity_bounds_the_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: {3}, raising=False)
    monkeypatch.setattr(cores.os, "cpu_count", lambda: 8)
    assert usable_cores() == 1
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: {0, 2, 5}, raising=False)
    assert usable_cores() == 3


def test_without_an_affinity_every_core_of_the_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delattr(cores.os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(cores.os, "cpu_count", lambda: 6)
    assert usable_cores() == 6
    monkeypatch.setattr(cores.os, "cpu_count", lambda: None)  # undeterminable
    assert usable_cores() == 1
