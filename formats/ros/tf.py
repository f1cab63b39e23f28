"""tf trees in 2-D: robot poses along a transform chain and static sensor mounts.

Pure functions over the transforms a log's ``/tf`` and ``/tf_static`` topics carry
(REP 105: ``map → odom → base_link → sensor frames``). Transforms are projected onto the
plane: x, y (m) and yaw (rad, CCW, from the quaternion). A link is *static* when it came
from ``/tf_static`` or never changes on ``/tf`` (e.g. a robot_state_publisher mount).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from formats.angles import wrap_angle
from formats.angles import yaw_from_quaternion as yaw_from_quaternion  # re-exported
from formats.arrays import F64, I64
from formats.contract import PoseBatch, SensorMount
from formats.ros.columns import TransformColumns

Pose2 = tuple[F64, F64, F64]  # x (m), y (m), yaw (rad)


@dataclass(frozen=True)
class Link:
    """Samples of one ``parent → child`` transform, sorted by stamp (ns), unique stamps.

    A static link holds a single sample (its last value).
    """

    parent: str
    child: str
    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    static: bool

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


def compose(a: Pose2, b: Pose2) -> Pose2:
    """``a ∘ b``: pose b (given in a's frame) expressed in a's parent frame."""
    ax, ay, ayaw = a
    bx, by, byaw = b
    c, s = np.cos(ayaw), np.sin(ayaw)
    return ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(ayaw + byaw)


def invert(a: Pose2) -> Pose2:
    """Inverse of a 2-D pose."""
    x, y, yaw = a
    c, s = np.cos(yaw), np.sin(yaw)
    return -(c * x + s * y), s * x - c * y, wrap_angle(-yaw)


def build_links(tables: Sequence[tuple[TransformColumns, bool]]) -> dict[str, Link]:
    """Links keyed by child frame from decoded tf batches ``(columns, from_tf_static)``.

    Repeated stamps keep the last sample. A child published under several parents (a
    broken tree) keeps the parent with the most samples.
    """
    rows: dict[tuple[str, str], list[tuple[I64, F64, F64, F64, bool]]] = {}
    for cols, static in tables:
        if cols.stamp_ns.shape[0] == 0:
            continue
        yaw = yaw_from_quaternion(cols.qx, cols.qy, cols.qz, cols.qw)
        pairs = cols.parent.astype(np.int64) * (len(cols.frames) + 1) + cols.child
        for key in np.unique(pairs):  # one iteration per frame pair, not per message
            m = pairs == key
            p, c = divmod(int(key), len(cols.frames) + 1)
            rows.setdefault((cols.frames[p], cols.frames[c]), []).append(
                (cols.stamp_ns[m], cols.x[m], cols.y[m], yaw[m], static)
            )
    best: dict[str, Link] = {}
    for (parent, child), parts in sorted(rows.items()):
        t = np.concatenate([p[0] for p in parts])
        x = np.concatenate([p[1] for p in parts])
        y = np.concatenate([p[2] for p in parts])
        yaw = np.concatenate([p[3] for p in parts])
        order = np.argsort(t, kind="stable")
        t, x, y, yaw = t[order], x[order], y[order], yaw[order]
        last = np.r_[t[1:] != t[:-1], True]  # keep the last sample of each stamp
        t, x, y, yaw = t[last], x[last], y[last], yaw[last]
        constant = bool(np.all(x == x[0]) and np.all(y == y[0]) and np.all(yaw == yaw[0]))
        static = any(p[4] for p in parts) or constant
        if static:
            t, x, y, yaw = t[-1:], x[-1:], y[-1:], yaw[-1:]
        link = Link(parent, child, t, x, y, yaw, static)
        old = best.get(child)
        if old is None or len(link) > len(old):
            best[child] = link
    return best


def ancestors(links: dict[str, Link], frame: str) -> list[str]:
    """``[frame, parent, grandparent, ...]`` up to the root of its tree."""
    out = [frame]
    while out[-1] in links:
        parent = links[out[-1]].parent
        if parent in out:  # a cycle: tf refuses these, so do we (stop at the loop)
            break
        out.append(parent)
    return out


def choose_root(links: dict[str, Link], base_frame: str) -> str:
    """The fixed frame for robot poses: ``map`` if it is an ancestor of the base frame,
    else ``odom``, else the topmost ancestor."""
    up = ancestors(links, base_frame)
    for name in ("map", "odom"):
        if name in up[1:]:
            return name
    return up[-1]


def chain(links: dict[str, Link], root: str, frame: str) -> list[Link]:
    """The links from ``root`` down to ``frame`` (root first); ValueError if not connected."""
    up = ancestors(links, frame)
    if root not in up:
        raise ValueError(f"{frame} is not below {root}")
    return [links[f] for f in reversed(up[: up.index(root)])]


def interpolate(link: Link, t_ns: I64) -> Pose2:
    """The link's pose at ``t_ns``: linear in position, shortest-arc in yaw; held
    constant outside its samples (and for static links)."""
    n = t_ns.shape[0]
    if link.static or len(link) == 1:
        return (np.full(n, link.x[0]), np.full(n, link.y[0]), np.full(n, link.yaw[0]))
    # Relative to the first stamp so the float64 interpolation keeps ns resolution.
    t0 = link.t_ns[0]
    tq = (t_ns - t0).astype(np.float64)
    ts = (link.t_ns - t0).astype(np.float64)
    yaw = np.interp(tq, ts, np.unwrap(link.yaw))
    return np.interp(tq, ts, link.x), np.interp(tq, ts, link.y), wrap_angle(yaw)


def compose_chain(links: Sequence[Link]) -> tuple[I64, F64, F64, F64]:
    """Poses of the end of a chain in its start frame: ``(t_ns, x, y, yaw)``.

    Sampled at the stamps of the fastest-changing link, restricted to the span every
    other moving link covers (tf does not extrapolate); the other links are
    interpolated. A chain of static links gives one pose at its latest stamp.
    """
    moving = [lk for lk in links if not lk.static and len(lk) > 1]
    if not moving:
        t = np.array([max((int(lk.t_ns[-1]) for lk in links), default=0)], np.int64)
    else:
        fastest = max(moving, key=len)  # first of equals: deterministic
        lo = max(int(lk.t_ns[0]) for lk in moving)
        hi = min(int(lk.t_ns[-1]) for lk in moving)
        t = fastest.t_ns[(fastest.t_ns >= lo) & (fastest.t_ns <= hi)]
    n = t.shape[0]
    pose: Pose2 = (np.zeros(n), np.zeros(n), np.zeros(n))
    for lk in links:
        pose = compose(pose, interpolate(lk, t))
    return t, pose[0], pose[1], pose[2]


def pose_batch(links: dict[str, Link], base_frame: str) -> PoseBatch:
    """Robot poses ``root → base_frame`` along the tf chain (root from :func:`choose_root`).

    Raises KeyError when no transform has ``base_frame`` as its child.
    """
    if base_frame not in links:
        raise KeyError(base_frame)
    root = choose_root(links, base_frame)
    t, x, y, yaw = compose_chain(chain(links, root, base_frame))
    return PoseBatch(t, x, y, yaw, parent_frame=root, child_frame=base_frame)


def static_mount(links: dict[str, Link], base_frame: str, frame: str) -> SensorMount | None:
    """Pose of ``frame`` in ``base_frame`` through static links only, None if there is no
    such path (not connected, or a moving link in between)."""
    if frame == base_frame:
        return SensorMount(0.0, 0.0, 0.0)
    up_base = ancestors(links, base_frame)
    up_frame = ancestors(links, frame)
    common = next((f for f in up_frame if f in set(up_base)), None)
    if common is None:
        return None
    to_base = chain(links, common, base_frame)
    to_frame = chain(links, common, frame)
    if not all(lk.static for lk in to_base + to_frame):
        return None
    one = np.zeros(1, np.int64)
    zero: Pose2 = (np.zeros(1), np.zeros(1), np.zeros(1))
    pb, pf = zero, zero
    for lk in to_base:
        pb = compose(pb, interpolate(lk, one))
    for lk in to_frame:
        pf = compose(pf, interpolate(lk, one))
    x, y, yaw = compose(invert(pb), pf)
    return SensorMount(float(x[0]), float(y[0]), float(yaw[0]))
