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
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['STALL_S', 'stream_heading']

#: A stream without a target for longer than this [s] stopped; a shorter gap is a stall.
STALL_S = 0.5


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
