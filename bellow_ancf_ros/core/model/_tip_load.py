"""What acts at the end effector besides the robot's own weight: a payload and a force.

Both are dead loads (constant in the base frame, like gravity) at the end
effector ``x_p`` (the top-plate centre plus the tool length along the
top-plate normal).  Their generalised force is eq. (14) with ``x_p`` there:
``x_p = r + h d3`` is linear in the plate coordinates, so
``Q = B^T F`` with ``B = [I, h I]`` on the plate's ``r`` and ``d3`` rows,
``F = m g + F_tip`` (:meth:`RobotModel.point_forces`).

A :class:`TipLoad` is a value: hashable and comparable, so that the
solvers' caches key on it and a warm start can tell whether it was made
under the same load; the continuation of the forward solver moves along a
straight line between two of them (:func:`lerp`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["MAX_TIP_FORCE_N", "TipLoad", "as_tip_load", "tip_load"]

#: Largest tip force accepted [N]: a soft robot of a few hundred grams under more
#: than 100 kg-force is a unit mistake, refused before any solve.
MAX_TIP_FORCE_N = 1e3


class TipLoad(NamedTuple):
    """A payload's mass [kg] and a force [N, base frame] at the end effector."""

    payload_kg: float = 0.0
    force_n: tuple = (0.0, 0.0, 0.0)

    @property
    def has_force(self) -> bool:
        """True when the force is not zero."""
        return any(f != 0.0 for f in self.force_n)

    def toward(self, other: TipLoad, t: float) -> TipLoad:
        """The load a fraction ``t`` of the way from here to ``other`` (a continuation step)."""
        return TipLoad(self.payload_kg + t * (other.payload_kg - self.payload_kg),
                       tuple(a + t * (b - a) for a, b in zip(self.force_n, other.force_n)))

    def describe(self) -> str:
        """``the payload of m kg`` and/or ``the tip force (fx, fy, fz) N``, for messages."""
        parts = []
        if self.payload_kg:
            parts.append(f"the payload of {self.payload_kg:g} kg")
        if self.has_force:
            parts.append("the tip force ({:g}, {:g}, {:g}) N".format(*self.force_n))
        return " and ".join(parts) or "its own weight"


def tip_load(payload_kg=0.0, tip_force_n=None) -> TipLoad:
    """A validated :class:`TipLoad`; a bad value raises ValueError (key, value, allowed)."""
    try:
        m = float(payload_kg)
    except (TypeError, ValueError):
        m = float("nan")
    if not (math.isfinite(m) and m >= 0):
        raise ValueError(f"payload must be a finite non-negative mass in kg, got {payload_kg}")
    if tip_force_n is None:
        return TipLoad(m)
    try:
        f = tuple(float(v) for v in tip_force_n)
    except (TypeError, ValueError):
        f = ()
    if len(f) != 3 or not all(math.isfinite(v) for v in f):
        raise ValueError(f"tip_force_n must be three finite numbers (N, base frame), "
                         f"got {tip_force_n!r}")
    size = math.sqrt(sum(v * v for v in f))
    if size > MAX_TIP_FORCE_N:
        raise ValueError(f"tip_force_n {f} has a magnitude of {size:.3g} N, more than "
                         f"{MAX_TIP_FORCE_N:g} N: refused as absurd (a unit mistake?)")
    return TipLoad(m, tuple(v + 0.0 for v in f))  # -0.0 -> 0.0: equal loads compare equal


def as_tip_load(load) -> TipLoad:
    """``load`` as a :class:`TipLoad`: a TipLoad as it is, a number as a payload mass [kg]."""
    return load if isinstance(load, TipLoad) else TipLoad(float(load))
