"""The robot's static mismatch carried to a new target: learned as parameters, not as an offset.

The integral loop (:class:`~._feedback.IntegralFeedback`) learns, at the
target it holds, the offset ``c`` that makes the model's inverse put the
robot there: the model, asked for ``p + c``, commands pressures ``P`` at
which the *model* stands at ``p + c`` and the *robot* at ``p``.  That offset
belongs to the pose it was learned at.  A robot whose stiffness, pitch
radii or ``D_a`` differ from its file's (the family's 6-10 %, the shipped
mismatched robots) is off by an amount that changes with the pose: after a
10 mm step the old offset is wrong by a few tenths of a millimetre, which
the loop then learns again, slowly (the shipped two-segment mismatched
robot, creep and play compensated, ``LoopSimulation``: 0.58 mm off 1.5 s
after a step with its nominal file, 0.06 mm with its own).

:class:`MismatchTransfer` reads the offset as a mismatch of the robot file's
parameters (:func:`~bellow_ancf_ros.core.model.parameter_keys.default_keys`:
the pitch radii, ``D_a``, ``D_eff`` and the stiffness scale, the keys
``bellow-ancf calibrate`` fits, and the masses' scale, whose sag a
two-segment robot shows: without it, the family's heavy two-segment robots
were carried the wrong way) and carries it to the new target.  With
``S(P)`` the change of the model's end-effector pose at the pressures ``P``
per relative change of each parameter (forward differences of forward
solves of the model with one parameter moved, warm-started from the
model's own solution)::

    robot(P) - model(P) = S(P) d          (to first order in the mismatch d)
    at the held target:  S(P_old) d = -c_old      (a few equations, more unknowns)
    d = argmin |W (S(P_old) d + c_old)|^2 + |SIGMA d / PRIOR|^2
    then REFINE Gauss-Newton steps with the model moved by d itself (F_d)
    at the new target:   c_new = -(F_d(P_new) - model(P_new))
    P_new from the model's inverse for the new target with c_new: asked again

``W`` weighs the z-axis's rotation by :data:`ROTATION_LENGTH_M` against the
position; ``PRIOR`` (10 %) is the size a file's parameters are off by
before calibration and ``SIGMA`` (0.05 mm) how well the offset is known,
so that the few equations pick the smallest mismatch that explains it.
The offset's share that no parameter explains (a motion-capture offset,
the play a regulator stopped in) is carried as it is.  The transfer is a
first-order guess that the loop then refines (the prior bounds it: a
mismatch the offset does not ask for is not invented); it is refused
(None) when a solve fails or the fit leaves the robot file's ranges.
"""

from __future__ import annotations

import numpy as np

from ..geometry import rotation_between
from ..model import RobotModel, parameter_keys as pk, robot_from_dict
from ..solve import ForwardResult, solve_forward

__all__ = ['MismatchTransfer', 'PRIOR', 'ROTATION_LENGTH_M', 'SIGMA_M']

#: Relative size of a robot file's parameter errors before calibration (the prior).
PRIOR = 0.10
#: A z-axis rotation of 1 rad weighs as this much position [m] (about a segment's length).
ROTATION_LENGTH_M = 0.1
#: The same for the masses' scale: a file's masses are rough (plates, fittings, tubing), and
#: the family's span half to twice the model's.
MASS_PRIOR = 0.5
#: How well the loop's correction is known [m]: the fit need not explain it closer than this.
SIGMA_M = 5e-5
#: Gauss-Newton steps of the fit with the fitted model after the linear one.
REFINE = 2
#: Relative step of the parameters' forward differences.
_STEP = 1e-4


class MismatchTransfer:
    """Carries the loop's correction from one held target to the next (module docstring).

    ``model``: the controller's model; ``keys``: the parameters a mismatch
    may lie in (default: those ``bellow-ancf calibrate`` fits and the masses'
    scale).
    """

    def __init__(self, model: RobotModel, keys=None) -> None:
        base = model.cfg.to_dict()
        self.model = model
        self.keys = pk.check_keys(base, list(keys or pk.default_keys(base) + [pk.MASS_SCALE]))
        nominal = [pk.get_value(base, k) for k in self.keys]
        self._base = base
        self._nominal = np.array(nominal)
        self._scales = np.array([pk.key_scale(k, v) for k, v in zip(self.keys, nominal)])
        self._prior = np.array([MASS_PRIOR if k == pk.MASS_SCALE else PRIOR for k in self.keys])
        # the models with one key moved, built here (not at the first jump, in the control path)
        self._models = [RobotModel(robot_from_dict(pk.with_values(
            base, [k], [v + _STEP * pk.key_scale(k, v)])), n_elements=model.n)
            for k, v in zip(self.keys, nominal)]
        self.use_orientation = model.cfg.n_segments > 1
        self.mismatch: dict = {}   # the last transfer's fitted relative changes, per key
        self._fit: RobotModel | None = None   # the last transfer's fitted model
        self._unexplained = None              # and the offset's share it did not explain
        self.transfers = 0
        self.refused = 0

    def sensitivity(self, fw: ForwardResult) -> np.ndarray | None:
        """``S(P)``: rows position (3) [and z-axis rotation (3)], a column per key.

        Per relative change of the key; None when a
        moved model's solve at ``fw``'s pressures fails.
        """
        columns = []
        for moved in self._models:
            off = self._offset(moved, fw)
            if off is None:
                return None
            columns.append(off / _STEP)
        return np.column_stack(columns)

    def _offset(self, model: RobotModel, fw: ForwardResult) -> np.ndarray | None:
        """``model``'s pose minus ``fw``'s at ``fw``'s pressures and load; None if it fails.

        Position (3) [and the rotation taking ``fw``'s z-axis onto ``model``'s (3)].
        """
        load = fw.load
        try:
            got = solve_forward(model, fw.pressures_pa, payload_kg=load.payload_kg,
                                tip_force_n=load.force_n, warm_start=fw, check_stability=False)
        except ValueError:   # (pressures the model refuses)
            return None
        if not got.converged:
            return None
        out = got.position - fw.position
        if self.use_orientation:
            out = np.concatenate([out, rotation_between(fw.z_axis, got.z_axis)])
        return out

    def fitted(self, d) -> RobotModel:
        """The controller's model with the keys moved by ``d`` (relative changes)."""
        return RobotModel(robot_from_dict(pk.with_values(
            self._base, self.keys, self._nominal + np.asarray(d) * self._scales)),
            n_elements=self.model.n)

    def transfer(self, held: ForwardResult, correction_m, correction_rad,
                 new: ForwardResult):
        """The correction at the new target: ``(position [m], z-axis rotation [rad] or None)``.

        ``held``: the model's solution at the commands of the held target
        (the corrected target's inverse); ``correction_*``: the loop's
        correction there (base frame); ``new``: the model's solution for the
        new target with the old correction.  The mismatch ``d`` is fitted at
        ``held`` (the linear fit, then :data:`REFINE` Gauss-Newton steps with
        the fitted model itself: a mass twice the file's is not linear in its
        sag), and the fitted model's offset from the model at ``new``'s
        pressures is the new correction.  None when a solve failed (the
        caller keeps the old correction).
        """
        S = self.sensitivity(held)
        if S is None:
            self.refused += 1
            return None
        e = -np.asarray(correction_m, dtype=float).reshape(3)   # robot minus model, at held
        w = np.ones(3)
        if self.use_orientation:
            e = np.concatenate([e, -np.asarray(correction_rad, dtype=float).reshape(3)])
            w = np.concatenate([w, np.full(3, ROTATION_LENGTH_M)])
        n = len(self.keys)
        # weighted least squares with the prior (d: relative changes of the keys)
        A = np.vstack([w[:, None] * S, np.diag(SIGMA_M / self._prior)])
        d = np.zeros(n)
        off = np.zeros_like(e)   # the fitted model's offset at held (0 for d = 0)
        for _ in range(1 + REFINE):
            b = np.concatenate([w * (e - off), -SIGMA_M / self._prior * d])
            d = d + np.linalg.lstsq(A, b, rcond=None)[0]
            try:
                fit = self.fitted(d)
            except ValueError:   # (a ConfigError: the fit left the robot file's ranges)
                fit = None
            off = None if fit is None else self._offset(fit, held)
            if off is None:
                self.refused += 1
                return None
        self._fit, self._unexplained = fit, e - off   # (carried as it is)
        got = self.again(new)
        if got is None:
            return None
        self.mismatch = dict(zip(self.keys, d))
        self.transfers += 1
        return got

    def again(self, new: ForwardResult):
        """The last :meth:`transfer`'s fit at other pressures: ``(position, rotation or None)``.

        The correction at a goal changes the pressures that reach it, and so
        the correction there: the caller solves the goal with the carried
        correction and asks again (a fixed point; the shipped mismatched
        robots' 10 mm step across the bend: the first answer leaves 26 % (one
        segment) and 14 % (two) of the change, two more 2 % and 3 %).  None
        when the solve fails; ``ValueError`` before a transfer.
        """
        if self._fit is None:
            raise ValueError('MismatchTransfer.again before a transfer: nothing was fitted')
        at_new = self._offset(self._fit, new)
        if at_new is None:
            self.refused += 1
            return None
        pred = at_new + self._unexplained
        c_new = -pred[:3]
        r_new = None
        if self.use_orientation:
            r_new = -pred[3:]
            z = new.z_axis / np.linalg.norm(new.z_axis)
            r_new = r_new - (r_new @ z) * z
        return c_new, r_new
