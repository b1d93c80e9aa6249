"""Forward predictions of a recording's samples and their parameter sensitivities.

:class:`RecordingModel` solves the forward problem (paper section IV.B) of
every sample for given values of robot-file parameters (keys of
:mod:`.parameter_keys`), warm-started from the same sample's last solution,
and differentiates the end-effector position and z-axis with respect to the
parameters:

* :meth:`RecordingModel.sensitivities`: the implicit function theorem on the
  equilibrium (eq. 25), ``R(x; theta) = 0  =>  dx/dtheta = -J^{-1} dR/dtheta``
  with the KKT Jacobian ``J`` of eq. (27) factorised once per sample (the
  converged solve's ``lu``).  ``dR/dtheta`` at fixed ``x`` (through stage 1,
  eqs. 10/24, the stiffnesses of eqs. 2/4, gravity, geometry) is a forward
  difference (relative step 1e-7) of residual evaluations of the model with
  the parameter moved: no solves.  The end effector moves with ``q`` and,
  for ``model.tool_length_mm``, directly.
* :meth:`RecordingModel.sensitivities_fd`: central differences of whole
  forward solves (the reference the first is tested against).

The last sensitivities also move the warm starts to first order
(``x + dx/dtheta * dtheta``).  No ROS import.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..model import RobotConfig, RobotModel, parameter_keys as pk, robot_from_dict
from ..solve import solve_forward

__all__ = ['RecordingModel']

_REL_STEP = 1e-7         # relative parameter step of the residual differences


class RecordingModel:
    """Forward predictions, sensitivities and residuals of one recording.

    ``cfg`` is the nominal robot, ``keys`` the fitted parameters, ``pressures_pa``
    (n, A).  Models for parameter values are built on demand (cached).
    """

    def __init__(self, cfg: RobotConfig, keys: Sequence[str], pressures_pa, n_elements=None):
        self.cfg = cfg
        self.base = cfg.to_dict()
        self.keys = pk.check_keys(self.base, list(keys))
        self.nominal = np.array([pk.get_value(self.base, k) for k in self.keys])
        self.scales = np.array([pk.key_scale(k, v) for k, v in zip(self.keys, self.nominal)])
        self.n_elements = cfg.n_elements if n_elements is None else int(n_elements)
        self.P = np.atleast_2d(np.asarray(pressures_pa, dtype=float))
        self._models: dict = {}
        self._warm: list = [None] * len(self.P)
        self._dx: list = [None] * len(self.P)   # (dx/dtheta, theta) of the last sensitivities
        self.solves = 0

    def config(self, values) -> RobotConfig:
        """Robot description with ``values`` of the keys (ConfigError if invalid)."""
        return robot_from_dict(pk.with_values(self.base, self.keys, values),
                               source='<calibration>')

    def model(self, values) -> RobotModel:
        """The robot model for ``values`` (cached; ConfigError if invalid)."""
        key = tuple(float(v) for v in values)
        if key not in self._models:
            if len(self._models) > 64:
                self._models.clear()
            self._models[key] = RobotModel(self.config(values), self.n_elements)
        return self._models[key]

    def solve(self, values, check_stability=False, give_up_after: int | None = None):
        """Forward solves of every sample; None for a sample whose solve failed.

        Each solve starts from the same sample's last solution, moved to first
        order by the last sensitivities (``x + dx/dtheta * dtheta``) when known.
        ``give_up_after``: once that many samples failed, the rest are not
        solved (None too).  A sample whose solve fails costs the most (a warm
        and then a cold solve, each to its budget: 0.3-0.4 s for two segments
        against about 2 ms converged), and a trial point of a fit far outside
        the robot's range fails at most of them.  The solutions become the
        next warm starts only when every sample converged: a point where one
        failed is one a fit refuses, and its solutions, far from the next
        point's, would lead the next solves to other equilibria (measured:
        a fit that then stalled at its start for 8 evaluations).
        """
        values = np.asarray(values, dtype=float)
        model = self.model(values)
        out, prev, failed = [], None, 0
        warm_before = list(self._warm), list(self._dx)
        for i, p in enumerate(self.P):
            if give_up_after is not None and failed >= give_up_after:
                out.extend([None] * (len(self.P) - i))
                break
            warm = self._warm[i] or prev
            if self._warm[i] is not None and self._dx[i] is not None:
                dv = values - self._dx[i][1]
                warm = dataclasses.replace(self._warm[i], x=self._warm[i].x + self._dx[i][0] @ dv)
            fw = solve_forward(model, p, model.cfg.payload, warm_start=warm,
                               check_stability=check_stability)
            self.solves += 1
            if not fw.converged and warm is not None:
                fw = solve_forward(model, p, model.cfg.payload, check_stability=check_stability)
                self.solves += 1
            if fw.converged:
                self._warm[i] = prev = fw
                self._dx[i] = None
                out.append(fw)
            else:
                out.append(None)
                failed += 1
        if failed:
            self._warm, self._dx = warm_before
        return out

    @staticmethod
    def pose_arrays(fws):
        """Positions and z-axes (n, 3) of solved samples (NaN where a solve failed)."""
        pos = np.full((len(fws), 3), np.nan)
        z = np.full((len(fws), 3), np.nan)
        for i, fw in enumerate(fws):
            if fw is not None:
                pos[i], z[i] = fw.position, fw.z_axis
        return pos, z

    def sensitivities(self, values, fws):
        """``d position/d theta``, ``d z/d theta`` (n, 3, k) by the implicit function theorem."""
        values = np.asarray(values, dtype=float)
        k = len(self.keys)
        h = _REL_STEP * self.scales
        moved = []
        for j in range(k):
            vp = values.copy()
            vp[j] += h[j]
            mp = self.model(vp)
            moved.append((mp, mp.stage1.stretch(self.P)))
        base = self.model(values)
        ee = base.plate_dofs[base.ee_plate]
        dpos = np.full((len(fws), 3, k), np.nan)
        dz = np.full((len(fws), 3, k), np.nan)
        for i, fw in enumerate(fws):
            if fw is None:
                continue
            dR = np.empty((base.N, k))
            direct_p = np.empty((3, k))
            r0 = base.evaluate(fw.x, fw.stretch, 1.0, base.cfg.payload, jacobian=False).residual
            p0 = base.end_effector(fw.q)[0]
            for j, (mp, lp) in enumerate(moved):
                rp = mp.evaluate(fw.x, lp[i], 1.0, mp.cfg.payload, jacobian=False).residual
                dR[:, j] = (rp - r0) / h[j]
                direct_p[:, j] = (mp.end_effector(fw.q)[0] - p0) / h[j]
            dx = -fw.lu.solve(dR)
            if fw is self._warm[i]:
                self._dx[i] = (dx, values)
            dq = dx[: base.nq]
            dz[i] = dq[ee[9:12]]
            dpos[i] = dq[ee[0:3]] + base.cfg.tool_length * dz[i] + direct_p
        return dpos, dz

    def sensitivities_fd(self, values, rel_step=1e-5):
        """The same sensitivities by central differences of whole forward solves."""
        values = np.asarray(values, dtype=float)
        n, k = len(self.P), len(self.keys)
        dpos, dz = np.zeros((n, 3, k)), np.zeros((n, 3, k))
        for j in range(k):
            h = rel_step * self.scales[j]
            res = []
            for s in (1.0, -1.0):
                v = values.copy()
                v[j] += s * h
                model = self.model(v)
                fws = [solve_forward(model, p, model.cfg.payload, warm_start=w,
                                     check_stability=False, tol=1e-12)
                       for p, w in zip(self.P, self._warm)]
                if not all(fw.converged for fw in fws):
                    raise RuntimeError(f'forward solve failed at {self.keys[j]} = {v[j]:g}')
                res.append(self.pose_arrays(fws))
            dpos[:, :, j] = (res[0][0] - res[1][0]) / (2 * h)
            dz[:, :, j] = (res[0][1] - res[1][1]) / (2 * h)
        return dpos, dz
