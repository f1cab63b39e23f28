"""Time stamps as text: exact decimal seconds ↔ int64 nanoseconds, one rule for every file.

Every text format sonarmap reads or writes (CSV logs, CARMEN logs, trajectory CSV and TUM)
carries time as decimal seconds. Converting through a float loses ~256 ns at epoch scale,
so both directions are exact: digits below the unit are rounded half away from zero and
exponent notation (``1.5e9``) is accepted, as :class:`decimal.Decimal` reads it.

:func:`stamps_behind` is the one meaning of a stamp going backwards, for every stream
read in log order (readings, poses, a CARMEN log's ODOM lines); :func:`ros_stamps_fit` the
one meaning of the stamps a ROS or MCAP message can carry, for every writer of them.
"""

from __future__ import annotations

from decimal import ROUND_HALF_UP, Decimal, InvalidOperation

import numpy as np
import numpy.typing as npt

from formats.arrays import I64, B

__all__ = ["ROS_TIME_END_NS", "ROS_TIME_MIN_NS", "format_time_s", "parse_time", "ros_stamps_fit",
           "stamps_behind"]

_INT64 = 2**63


def parse_time(text: str, digits: int = 9) -> int:
    """Exact int of a decimal time text scaled by ``10**digits`` (9: seconds → ns).

    ValueError, with a message fit for "<file>: line N: column 't': <message>", when the
    text is not a number, not finite or outside int64.
    """
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        what = "an empty field" if not text.strip() else repr(text)
        raise ValueError(f"expected a time, found {what}") from None
    if not d.is_finite():
        raise ValueError(f"{text!r} is not a finite time")
    n = int(d.scaleb(digits).to_integral_value(rounding=ROUND_HALF_UP))
    if not -_INT64 <= n < _INT64:
        raise ValueError(f"{text!r} is out of the int64 ns range")
    return n


def format_time_s(t_ns: npt.ArrayLike) -> list[str]:
    """Exact decimal seconds ``<sec>.<9-digit nsec>`` of int64 nanosecond stamps."""
    out = []
    for v in np.asarray(t_ns, dtype=np.int64).tolist():
        sign = "-" if v < 0 else ""
        sec, nsec = divmod(abs(v), 1_000_000_000)
        out.append(f"{sign}{sec}.{nsec:09d}")
    return out


def stamps_behind(t: I64, newest: int | None) -> tuple[B, I64, int | None]:
    """The one meaning of "stamps going backwards": a stamp older than the running maximum
    of the stamps before it (``newest``: the maximum of earlier batches, None if none).

    Returns the mask of such stamps, how far each is behind (ns, 0 where it is not) and the
    running maximum after ``t``. One jump back followed by rising stamps that stay below
    the earlier maximum flags every one of them: they are all older than a stamp already
    seen.
    """
    if t.shape[0] == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64), newest
    head = t[:1] if newest is None else np.array([newest], dtype=np.int64)
    before = np.maximum.accumulate(np.r_[head, t[:-1]])  # max of all earlier stamps
    behind = np.maximum(before - t, 0)
    return behind > 0, behind, int(max(before[-1], t[-1]))


# builtin_interfaces/Time holds int32 seconds (ROS 1's uint32 seconds hold its non-negative
# part); MCAP and rosbag log times are unsigned nanoseconds. Beyond, a stamp would wrap or
# the serializer fail.
ROS_TIME_MIN_NS = -(2**31) * 1_000_000_000
ROS_TIME_END_NS = 2**31 * 1_000_000_000  # exclusive


def ros_stamps_fit(t_min_ns: int, t_max_ns: int, *, log_time: bool) -> bool:
    """Whether stamps ``t_min_ns … t_max_ns`` fit a ROS 2 ``Time`` and, with ``log_time``
    (stamps that are also a message's MCAP or bag log time), are not negative either."""
    low = 0 if log_time else ROS_TIME_MIN_NS
    return low <= t_min_ns and t_max_ns < ROS_TIME_END_NS
