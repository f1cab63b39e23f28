"""WorkShare sizes the calling thread's part of a group's divisible work so that it and the
worker thread finish together, from the seconds measured on the groups before."""

from __future__ import annotations

import pytest

from pipeline.mapper.work_share import MIN_SHARE, WorkShare


def test_the_first_group_is_halved_then_the_share_balances_the_threads() -> None:
    share = WorkShare()
    assert share.share == 0.5
    # own 2 s; the divisible work costs 10 s on either thread: 2 + s·10 = (1 − s)·10
    share.update(2.0, 5.0, 5.0, 0.5)
    assert share.share == pytest.approx(0.4)
    # Same costs measured at the new share: the same answer.
    share.update(2.0, 4.0, 6.0, 0.4)
    assert share.share == pytest.approx(0.4)


def test_unequal_paces_move_the_share_toward_the_slower_part() -> None:
    share = WorkShare()
    # No own work, but this thread's half took 3 s and the worker's 1 s (its part is the
    # cheaper one): this thread keeps a quarter, 0 + s·6 = (1 − s)·2.
    share.update(0.0, 3.0, 1.0, 0.5)
    assert share.share == pytest.approx(0.25)


def test_the_share_stays_within_its_bounds_and_ignores_degenerate_groups() -> None:
    share = WorkShare()
    share.update(100.0, 1.0, 1.0, 0.5)  # own work alone exceeds the worker's part
    assert share.share == MIN_SHARE
    share = WorkShare()
    share.update(0.0, 1.0, 0.0, 0.5)  # the worker's part cost nothing
    assert share.share == MIN_SHARE
    share = WorkShare()
    share.update(0.0, 0.0, 5.0, 0.5)
    assert share.share == 1.0 - MIN_SHARE
    share = WorkShare()
    share.update(1.0, 2.0, 3.0, 0.0)  # nothing was divided: nothing to learn
    share.update(1.0, 2.0, 3.0, 1.0)
    assert share.share == 0.5


def test_the_means_remember_the_groups_before() -> None:
    share = WorkShare()
    share.update(0.0, 1.0, 1.0, 0.5)
    assert share.share == pytest.approx(0.5)
    share.update(0.0, 1.0, 3.0, 0.5)  # one slow worker group moves the share part way
    assert 0.5 < share.share < 0.75
