"""Decimal seconds ↔ int64 ns: exact both ways, one rule for every text format."""

from __future__ import annotations

import pytest

from formats.stamps import format_time_s, parse_time


def test_time_formatting_is_exact() -> None:
    assert format_time_s([0, 1, 1_500_000_000, -1, -2_000_000_001]) == [
        "0.000000000",
        "0.000000001",
        "1.500000000",
        "-0.000000001",
        "-2.000000001",
    ]
    big = 1_700_000_000_999_999_999
    assert format_time_s([big]) == ["1700000000.999999999"]


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("1700000000.000000001", 1_700_000_000_000_000_001),  # a float would lose the 1 ns
        ("12.5", 12_500_000_000),
        (" 3 ", 3_000_000_000),
        (".25", 250_000_000),
        ("-2.000000001", -2_000_000_001),
        ("+1.", 1_000_000_000),
        ("1.5e9", 1_500_000_000_000_000_000),
        ("0.0000000015", 2),  # below 1 ns: half away from zero
        ("-0.0000000015", -2),
        ("0.0000000014", 1),
    ],
)
def test_parse_time_is_exact_and_rounds_half_away_from_zero(text: str, ns: int) -> None:
    assert parse_time(text) == ns


def test_parse_time_round_trips_formatting() -> None:
    stamps = [0, 1, -1, 1_700_000_000_123_456_789, -(2**62)]
    assert [parse_time(s) for s in format_time_s(stamps)] == stamps


def test_parse_time_other_units() -> None:
    # digits = the power of ten from the text's unit to ns: µs → 3, ms → 6, ns → 0
    assert parse_time("1.5", digits=3) == 1500
    assert parse_time("0.0015", digits=3) == 2  # half away from zero
    assert parse_time("1700000000123", digits=6) == 1_700_000_000_123_000_000


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "expected a time, found an empty field"),
        ("12:00", "expected a time, found '12:00'"),
        ("nan", "'nan' is not a finite time"),
        ("inf", "'inf' is not a finite time"),
        ("1e12", "'1e12' is out of the int64 ns range"),
    ],
)
def test_parse_time_refuses(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=f"^{message}$"):
        parse_time(text)
