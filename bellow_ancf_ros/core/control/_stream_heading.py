"""Where a stream of stamped targets was heading: what a jump is measured from.

A target that is far from where its stream was heading is a jump (a step
of the planner); one that is where the stream was heading is the stream
going on, however late it comes.  The heading is the newest target plus the
stream's last step scaled to the time since it (the targets' own times):
a 50 Hz stream on the two-segment circle at 10x lands within 0.11 mm of it.
A late target misses it by the stream's acceleration: ``a g (g + h) / 2``
after a gap ``g`` since a step ``h`` (the last step's chord is the velocity
half a step back).  On a busy computer a planner stalls for 0.1 s and more
(the busy bench: 104-156 ms), and on that circle a target 120 ms after the one
before lies 2.2 mm off the heading: read as a jump, the stream's next 1.2 s
became a move that lagged the circle by up to 32 mm (simulated; 0.74 mm
RMSE without the stall, 15.9 mm with it).  So the allowance for the
acceleration, estimated from the last three targets, is added to the jump
threshold.  A stream silent for longer than :data:`STALL_S` stopped (the
robot came to rest at its last target): its heading is that target.

A lab's planner computes its poses on a timer and stamps each when it
sends it: on a busy computer some sends come late (a lab-style busy run:
0.4 ms median, 5.8-8.1 ms p99, up to 187 ms), and a late send's stamp puts
the stream's last step off its time.  The target after it, on time and a
tick or two on, lay 2.7-3.4 mm off the heading by the stamps; in a
simulated closed loop (two segments, 10x circle, one send in 33 late by
3-40 ms) 6-14 such false jumps in 7 s made the circle moves, 6.7-24 mm RMSE
against 0.75 mm.  So a stream of six targets or more is read by its
timer's grid where its poses lie smoother on it (:func:`stream_times`),
a stamp is taken as the latest its pose's time can be (the target is
tested against the heading over the whole time since the newest target,
:func:`stream_jumps`), and a target is a jump only if it also misses the
heading of the targets before the newest (whose own time a late send may
have put off): in that loop, no false jump, 0.74-1.35 mm RMSE.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['STALL_S', 'stream_heading', 'stream_jumps', 'stream_times']

#: A stream without a target for longer than this [s] stopped; a shorter gap is a stall.
STALL_S = 0.5
#: The window [s] (at least six targets) over which a stream's smoothness is judged.
SMOOTH_WINDOW_S = 0.1
#: A stream this close [m RMS] to a cubic by its stamps over that window is read by them
#: (the two-segment circle at 10x: 0.05 um off its cubic over 0.1 s).
SMOOTH_M = 2.0e-7


def stream_grid(stamps: np.ndarray) -> tuple | None:
    """The regular grid a stream's stamps scatter about (a planner's timer), or None.

    Returns ``(grid times, trusted)``: each stamp's tick, and whether the
    stamp is at most half an interval after it (a later one's tick is a
    guess).

    ``stamps`` ascending.  The first line runs through the stamps within a
    quarter interval of the median line (each interval counted as a whole
    number of the median one: a dropped or skipped target skips one, from
    1.75 of them on; its slope the median over pairs of stamps half the
    stream apart).  Then, three times: each stamp goes on the last tick at or
    before it (a stamp is never earlier than its pose's time; a quarter
    interval is allowed for the line's own scatter; a late one that lands on
    its successor's tick goes on the one before), and the line is fitted by
    least squares to the stamps within a quarter interval of their ticks
    (the others are late sends: a busy computer kept the planner waiting).
    A stamp later than its tick by nearly an interval or more may be on the
    wrong one.  The grid is moved to the earliest stamp on the line (its
    pose's time, near enough: the others were sent later).  None: fewer than
    six stamps, or fewer than two thirds of them on the line.
    """
    ts = np.asarray(stamps, dtype=float)
    n = len(ts)
    if n < 6:
        return None
    gaps = np.diff(ts)
    b = float(np.partition(gaps, len(gaps) // 2)[len(gaps) // 2])
    if not b > 0:
        return None
    # (a gap counts as a skipped tick from 1.75 intervals on: a send late by more than half
    # an interval is no skip)
    k = np.concatenate(([0.0], np.cumsum(np.maximum(1.0, np.floor(gaps / b + 0.25)))))
    # the slope: the median over pairs half the stream apart (the median interval alone is
    # off by the jitter: 3 ms late on average at 50 Hz put it 0.5 ms off, 15 ms over 30)
    m = n // 2
    b = float(np.median((ts[m:] - ts[:n - m]) / (k[m:] - k[:n - m])))
    a = float(np.partition(ts - b * k, n // 2)[n // 2])   # (a median line: late sends aside)
    sel = np.abs(ts - a - b * k) <= 0.25 * b
    if sel.sum() < 3:
        return None
    early = 0.25   # how far before its tick [intervals] a stamp may lie (the line's own scatter)
    idx = np.arange(n)
    for _ in range(3):
        kk, tt = k[sel], ts[sel]
        dk = kk - kk.mean()
        b = float(dk @ (tt - tt.mean()) / (dk @ dk))
        a = float(tt.mean() - b * kk.mean())
        if not b > 0:
            return None
        k = np.floor((ts - a) / b + early)   # (the tick at or before it)
        # (a late stamp on its successor's tick goes on the one before: k_i <= k_(i+1) - 1)
        k = idx + np.minimum.accumulate((k - idx)[::-1])[::-1]
        res = (ts - a) / b - k
        sel = (res >= -early) & (res <= 0.25)
        if 3 * sel.sum() < 2 * n:
            return None
    a += b * float(res[sel].min())   # (at its earliest stamp: the others came later)
    return a + b * k, (res >= -early) & (res <= 0.5)


def off_cubic(times: np.ndarray, positions: np.ndarray) -> float:
    """RMS distance [m] of the positions from their cubic in time over the newest ones.

    Over :data:`SMOOTH_WINDOW_S` before the newest, at least the last six;
    0 with fewer than six.
    """
    if len(times) < 6:   # (a cubic through five leaves one degree of freedom: too few to judge)
        return 0.0
    t = np.asarray(times, dtype=float) - times[-1]
    sel = t >= min(-SMOOTH_WINDOW_S, t[-6])
    tau = t[sel] / SMOOTH_WINDOW_S   # (scaled to [-1, 0], about the newest: the normal
    V = tau[:, None] ** np.arange(4)   # equations of a 4x4 are then well within double)
    P = positions[sel] - positions[-1]
    # (least squares, not the normal equations' solve: times on fewer than three instants made
    # them singular, and the node's solve raised LinAlgError: 4 times in a make demo run)
    r = V @ np.linalg.lstsq(V, P, rcond=None)[0] - P
    return float(np.sqrt(np.mean(r ** 2) * 3))


def stream_times(stamps: np.ndarray, positions: np.ndarray) -> tuple:
    """The times to read a stream by: ``(times, trusted, on_grid, off_cubic by them)``.

    A planner that computes its poses on a timer and stamps each when it
    sends it (later by however long its computer kept it waiting) gives
    stamps that scatter about its timer's grid, and its poses lie on a
    smooth path by the grid, not by the stamps: the grid
    (:func:`stream_grid`) where the poses whose stamps are on it lie closer
    to a cubic by it (:func:`off_cubic`) than all do by their stamps; else
    the stamps (a planner that stamps each pose with its own time, however
    late its timer fires).  ``trusted``: the samples whose times are known
    (on the grid: those stamped at most half an interval after their ticks,
    six of them at least; by the stamps: all).
    """
    stamps = np.asarray(stamps, dtype=float)
    off = off_cubic(stamps, positions)
    if off <= SMOOTH_M:   # (smooth by its stamps already: no grid can do better)
        return stamps, np.ones(len(stamps), dtype=bool), False, off
    grid = stream_grid(stamps)
    if grid is not None and grid[1].sum() >= 6:   # (fewer: too few to judge the grid by)
        times, on = grid
        off_grid = off_cubic(times[on], positions[on])
        if off_grid < off:
            return times, on, True, off_grid
    return stamps, np.ones(len(stamps), dtype=bool), False, off


def stream_heading(hist, t: float):
    """Where the stream ``hist`` was heading at ``t``: ``(position, z, allow_m, allow_rad)``.

    ``hist``: its newest samples ``(time, position (3,), z-axis (3,) or
    None)``, oldest first, one at least, none across a jump (the last three
    are read).  ``allow_*``: how far a target of the stream may miss
    the heading by the stream's acceleration (module docstring); 0 with
    fewer than three samples.  After :data:`STALL_S` without a target, or
    with one sample: the newest sample itself.
    """
    t1, p1, z1 = hist[-1]
    gap = float(t) - t1
    if len(hist) < 2 or not (0.0 <= gap <= STALL_S):
        return p1, z1, 0.0, 0.0
    t0, p0, z0 = hist[-2]
    h = t1 - t0
    if not (0.0 < h < math.inf):
        return p1, z1, 0.0, 0.0
    k = gap / h
    head_p = p1 + k * (p1 - p0)
    head_z = z1 if z1 is None or z0 is None else z1 + k * (z1 - z0)
    allow_m = allow_rad = 0.0
    if len(hist) >= 3:
        tm, pm, zm = hist[-3]
        span = t1 - tm
        if h < span < math.inf:
            scale = 0.5 * gap * (gap + h) / (0.5 * span)   # a g (g + h) / 2, a = dv / (span/2)
            allow_m = scale * float(np.linalg.norm((p1 - p0) / h - (p0 - pm) / (span - h)))
            if z1 is not None and z0 is not None and zm is not None:
                allow_rad = scale * float(np.linalg.norm((z1 - z0) / h - (z0 - zm) / (span - h)))
    return head_p, head_z, allow_m, allow_rad


def stream_jumps(hist, t: float, position, z_axis=None, jump_m: float = math.inf,
                 jump_rad: float = math.inf, read: tuple | None = None) -> bool:
    """Whether a target at stamp ``t`` jumps from where the stream ``hist`` was heading.

    A jump misses the heading by more than ``jump_m`` (or its z-axis by
    ``jump_rad``) plus the allowance for the stream's acceleration
    (:func:`stream_heading`).  ``hist``: the stream's newest samples
    ``(stamp, position, z-axis or None)``, oldest first, none across a
    jump, read by :func:`stream_times` (six or more: its timer's grid, where
    the stamps scatter about one; the samples whose times it trusts).  A
    stamp is never earlier than its pose's time (a pose is stamped when it
    is computed, or later when it is sent): the target is the stream's pose
    at some time between the newest sample's and ``t``, so it misses by its
    distance from the heading's path over that time.  And the newest
    sample's own time may be wrong (sent late, its stamp some ticks after
    its pose, however its grid reads it): the target is a jump only if it
    also misses the heading of the samples before it, from the time of the
    one before.  ``read``: ``(times, trusted)`` of ``hist`` by
    :func:`stream_times`, if known.
    """
    p = np.asarray(position, dtype=float)
    z = None if z_axis is None else np.asarray(z_axis, dtype=float)
    stamps = np.array([s[0] for s in hist])
    times, trusted = stamps, [True] * len(hist)
    if read is not None:
        times, trusted = read
    elif len(hist) >= 6:
        times, trusted, _, _ = stream_times(stamps, np.array([s[1] for s in hist]))
    read = [(float(tt), s[1], s[2]) for tt, s, ok in zip(times, hist, trusted) if ok]

    def miss(x, x1, head):   # distance from x to the segment x1 -> head
        d = head - x1
        dd = float(d @ d)
        f = 0.0 if dd == 0.0 else min(max(float((x - x1) @ d) / dd, 0.0), 1.0)
        return float(np.linalg.norm(x - x1 - f * d))

    for basis in (read, read[:-1]) if len(read) >= 3 else (read,):
        t1, p1, z1 = basis[-1]
        head_p, head_z, allow_m, allow_rad = stream_heading(basis, max(float(t), t1))
        if miss(p, p1, head_p) <= jump_m + allow_m and (
                z is None or head_z is None or miss(z, z1, head_z) <= jump_rad + allow_rad):
            return False
    return True
