"""The physical range of a number read at the edge (a config key, a header field, a CSV
column), declared once and checked where the number enters.

A :class:`Range` is an interval with open or closed ends, a unit, and optionally a
meaning for 0 outside it (``zero="automatic"``). NaN and ±inf are never in a range.
:meth:`Range.rule` is the text an error shows: ``must be in (0, 1] m (0 = automatic)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Range:
    """``lo`` .. ``hi`` (``lo_open``/``hi_open``: excluded), in ``unit``."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    zero: str = ""  # what 0 means when 0 lies outside the interval ('' = nothing)

    def holds(self, value: float) -> bool:
        """Whether ``value`` is a finite number in the range (or 0 with a meaning)."""
        if self.zero and value == 0:
            return True
        if not math.isfinite(value):
            return False
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return above and below

    def rule(self) -> str:
        """``must be in [lo, hi] unit`` (with what 0 means, when it means something)."""
        left = "(" if self.lo_open else "["
        right = ")" if self.hi_open else "]"
        unit = f" {self.unit}" if self.unit else ""
        zero = f" (0 = {self.zero})" if self.zero else ""
        return f"must be in {left}{_num(self.lo)}, {_num(self.hi)}{right}{unit}{zero}"


def _num(v: float) -> str:
    """``v`` as a rule shows it: integer limits near powers of two as ``2**31 - 1``."""
    if float(v).is_integer() and abs(v) >= 1 << 20:
        n = int(abs(v))
        sign = "-" if v < 0 else ""
        if n & (n - 1) == 0:
            return f"{sign}2**{n.bit_length() - 1}"
        if (n + 1) & n == 0:
            return f"{sign}2**{n.bit_length()} - 1"
    return f"{v:g}"


# Physical ranges shared by the configuration and the files sonarmap reads.
#: A map cell: 1 mm (finer is no sonar map) to 100 m.
CELL_M = Range(1e-3, 100, "m")
#: A map coordinate (an origin, an extent, a pose): within 10 000 km of the map frame.
COORD_M = Range(-1e7, 1e7, "m")
#: A sensor's mount in the robot's base frame: on a robot, within 100 m of its centre.
MOUNT_M = Range(-100, 100, "m")
#: A beam's range limit (r_min, r_max; 0 = from the log where configured): a sonar's reach.
LIMIT_M = Range(0, 1000, "m")
#: An angle read from a log (a yaw): any turn count whose radians keep their precision.
ANGLE_RAD = Range(-1e6, 1e6, "rad")


def open_range(lo: float, hi: float, unit: str = "", zero: str = "") -> Range:
    """``(lo, hi)``: both ends excluded."""
    return Range(lo, hi, unit, lo_open=True, hi_open=True, zero=zero)


def above(lo: float, hi: float, unit: str = "", zero: str = "") -> Range:
    """``(lo, hi]``: positive quantities (``lo`` excluded)."""
    return Range(lo, hi, unit, lo_open=True, zero=zero)
