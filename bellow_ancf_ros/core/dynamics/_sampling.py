"""A sampled simulation: the end effector's motion at fixed instants (docs/dynamics.md).

:func:`sample_motion` advances a started :class:`GeneralizedAlpha` to the
end time and records the end effector (position, z-axis) at the start and at
every ``sample_s``, and the energy and the constraint violation at every
``check_s`` (default: every sample).  The samples fall on steps: when the
sampling interval is not a whole number of steps, the step is shortened to
``sample_s / ceil(sample_s / step_s)`` (a constant step keeps the
integrator's factorisation).  A failed step ends the run at the last
converged sample; what was computed is returned with the failure's status.

:func:`piecewise_linear` turns a table of pressures over time into the
input function of :meth:`GeneralizedAlpha.advance` (linear between rows,
held at the first and last row outside them).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ._integrator import GeneralizedAlpha, StepReport

__all__ = ["SampledMotion", "sample_motion", "piecewise_linear", "sampling_step"]


@dataclass
class SampledMotion:
    """The end effector's motion at the sample instants (SI units).

    ``times_s`` (n,), ``positions_m`` (n, 3), ``z_axes`` (n, 3) (the end
    effector's z-axis, base frame), ``pressures_pa`` (n, A) (the input at
    each sample), ``energy_j`` (n,) (total energy, eqs. 15-17 plus kinetic,
    at the checked samples: NaN between checks), ``constraint_violation``
    (largest ``|C(q)|`` over the checked samples); the first and the last
    sample are always checked; the pressures are NaN when the run was given
    no pressures;
    ``report``: the integrator's :class:`StepReport` of the whole run;
    ``step_s``: the step used; ``step_wall_s``: wall time of each step (the
    run's mean: the steps run compiled, without Python between them).
    """

    times_s: np.ndarray
    positions_m: np.ndarray
    z_axes: np.ndarray
    pressures_pa: np.ndarray
    energy_j: np.ndarray
    constraint_violation: float
    report: StepReport
    step_s: float
    step_wall_s: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    @property
    def success(self) -> bool:
        return self.report.success

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second of the run."""
        span = float(self.times_s[-1] - self.times_s[0]) if len(self.times_s) else 0.0
        return span / self.report.wall_s if self.report.wall_s > 0 else math.inf

    def samples(self) -> list:
        """``[{"t_s", "position_m", "z_axis"}, ...]`` (the CLI's JSON samples)."""
        return [{"t_s": float(t), "position_m": [float(v) for v in x],
                 "z_axis": [float(v) for v in z]}
                for t, x, z in zip(self.times_s, self.positions_m, self.z_axes)]


def sampling_step(step_s: float, sample_s: float | None) -> float:
    """The step that puts the samples on steps: ``sample_s / ceil(sample_s / step_s)``."""
    if sample_s is None:
        return float(step_s)
    if not (math.isfinite(sample_s) and sample_s > 0):
        raise ValueError(f"sample_s = {sample_s!r} is not allowed; allowed: a positive time [s]")
    k = max(1, math.ceil(sample_s / step_s * (1 - 1e-12)))
    return float(sample_s) / k


def piecewise_linear(times_s, values):
    """``f(t)``: ``values`` (n, A) linear in ``t`` between ``times_s``, held outside them.

    Raises ValueError when the times are not increasing or the shapes differ.
    """
    t = np.asarray(times_s, dtype=float).ravel()
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    if len(t) == 0:
        raise ValueError("no rows")
    if np.any(np.diff(t) <= 0):
        raise ValueError("the times must increase strictly from row to row")
    cols = v.T.copy()

    def f(time_s):
        return np.array([np.interp(time_s, t, c) for c in cols])
    return f


def sample_motion(integrator: GeneralizedAlpha, t_end: float, sample_s: float | None = None,
                  pressures_pa=None, load=None, time_budget_s: float | None = None,
                  check_s: float | None = None) -> SampledMotion:
    """Advance a started ``integrator`` to ``t_end`` and sample the end effector (module doc).

    Parameters
    ----------
    integrator : a :class:`GeneralizedAlpha` after ``start`` or ``start_released``.
    t_end : end time [s].
    sample_s : sampling interval [s]; default: every step.  The integrator's
        step is shortened to :func:`sampling_step` when needed.
    pressures_pa, load : the inputs, as :meth:`GeneralizedAlpha.advance` takes them.
    time_budget_s : wall-clock budget of the whole run.
    check_s : interval [s] of the energy and constraint checks
        (:meth:`GeneralizedAlpha.checks`: some 17 us each for one segment,
        where a step takes some 80 us): at the first and the last sample and
        at the first sample at or after each further multiple of ``check_s``;
        default: every sample.

    Returns
    -------
    SampledMotion
        Whatever was computed; ``report.status`` says whether the run
        reached ``t_end``.
    """
    ig = integrator
    if ig.state is None:
        raise RuntimeError("call start(fw) first")
    if check_s is not None and not (math.isfinite(check_s) and check_s > 0):
        raise ValueError(f"check_s = {check_s!r} is not allowed; allowed: a positive time [s]")
    ig.step_s = sampling_step(ig.step_s, sample_s)
    every = ig.step_s if sample_s is None else float(sample_s)
    model = ig.model
    t0 = time.perf_counter()
    c0 = dict(ig.counters)
    st = ig.state
    t_start = st.t
    n = max(0, int(round((t_end - t_start) / every)))
    ends = np.array([min(t_start + k * every, t_end) if k < n else t_end
                     for k in range(1, n + 1)], dtype=float)
    gap = every if check_s is None else float(check_s)
    check = np.zeros(n, dtype=bool)
    next_check = t_start + gap
    for k, t_k in enumerate(ends.tolist()):   # the first sample at or after each multiple
        t = t_k + 1e-9 * every                  # of check_s, give or take roundoff; the last
        if k == n - 1 or t >= next_check:
            check[k] = True
            next_check = t_start + gap * (math.floor((t - t_start) / gap) + 1)
    total, passage = ig.advance_through(ends, pressures_pa=pressures_pa, load=load,
                                        time_budget_s=time_budget_s, check=check)
    e0, c_0 = ig.checks(st)
    times = np.r_[t_start, passage.times_s]
    x, rot = model.end_effectors(np.vstack([st.q[model.end_effector_dofs], passage.plate]))
    energy = np.r_[e0["total_j"], passage.checks[:, 0] + passage.checks[:, 1]]
    violations = np.r_[c_0, passage.checks[:, 2]]
    if pressures_pa is None:   # the stretches are given, not the pressures
        pres = np.full((len(times), model.A), np.nan)
    elif callable(pressures_pa):
        first = np.asarray(pressures_pa(t_start), dtype=float)
        pres = np.vstack([first] + ([passage.pressures_pa] if len(passage.times_s) else []))
    else:
        pres = np.tile(np.asarray(pressures_pa, dtype=float), (len(times), 1))
    if ig.state.t > times[-1]:   # stopped between samples: the state it stopped at, checked
        (xs, rs), (e, c) = ig.end_effector(), ig.checks()
        times = np.r_[times, ig.state.t]
        x, rot = np.vstack([x, xs]), np.concatenate([rot, rs[None]])
        energy, violations = np.r_[energy, e["total_j"]], np.r_[violations, c]
        p_last = (np.full(model.A, np.nan) if pressures_pa is None else
                  np.asarray(pressures_pa(ig.state.t) if callable(pressures_pa)
                             else pressures_pa, dtype=float))
        pres = np.vstack([pres, p_last])
    elif math.isnan(energy[-1]):   # the last sample is checked too (a time budget ran out)
        e, c = ig.checks()
        energy[-1] = e["total_j"]
        violations[-1] = c
    total.wall_s = time.perf_counter() - t0
    for key in ("steps", "iterations", "factorizations"):
        setattr(total, key, ig.counters[key] - c0[key])
    total.message = total.status.message if total.success else (
        f"{total.status.message} at t = {ig.state.t:.6g} s")
    steps = max(total.steps, 1)
    return SampledMotion(times_s=times, positions_m=x, z_axes=rot[:, :, 2], pressures_pa=pres,
                         energy_j=energy, constraint_violation=float(np.nanmax(violations)),
                         report=total, step_s=float(ig.step_s),
                         step_wall_s=np.full(total.steps, total.wall_s / steps))
