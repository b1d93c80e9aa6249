"""Calibration of the model to recordings of a real robot (robot parameters + mocap frame).

Data: quasi-static samples (:mod:`.recordings`): pressures ``P_i`` and the
end-effector pose measured in the motion-capture frame, position ``m_i`` and
z-axis ``n_i`` (third column of the measured rotation).  Unknowns: scalars
``theta`` of the robot file by key (:mod:`.parameter_keys`; default: pitch
radius, ``D_a``, ``D_eff``, stiffness scale) and, always, the pose of the
base frame in the mocap frame, ``(R, t)``, 6 numbers.  Residuals, for every
sample, with the forward model's end-effector position ``r_i(theta)`` and
z-axis ``z_i(theta)`` in the base frame (paper section IV.B)::

    e_pos = (R r_i + t - m_i) / sigma_p,     e_z = (R z_i - n_i) / sigma_z

minimised by ``scipy.optimize.least_squares``.  ``R = exp([w]) R0``
with ``R0, t0`` from a rigid (Kabsch) alignment of the nominal model's
predictions to the measurements; the ``w``-derivative uses the left Jacobian
of SO(3), exactly.  ``sigma_p``, ``sigma_z`` are re-estimated from the
residuals of each group and the fit repeated until they settle (at most
three rounds), so the reported uncertainties rest on the measured scatter.

Sensitivities (the Jacobian's robot columns) come from the model
(:mod:`.sensitivities`): the implicit function theorem on the equilibrium
(eq. 25) with one factorisation of the KKT matrix (eq. 27) per sample.
Forward solves are warm-started from the same sample's solution at the
previous parameters, moved to first order by the sensitivities.

Uncertainty: the posterior covariance ``(J^T J / s^2 + P)^-1`` of the
weighted problem (pseudo-inverse), ``s^2 = SSR/(m - n)`` over the ``m`` data
residuals and ``n`` parameters, ``P`` the weak prior (:data:`PRIOR_SIGMA`: 20 %
of a non-zero nominal value, 1 sigma; none on zero nominal values), which
keeps directions the data cannot see at the nominal value; 95 % intervals
with Student's ``t`` (``m - n`` degrees of freedom).  Parameters the data
cannot separate are named in ``warnings`` (from the data alone, without the
prior): pairs with ``|correlation| > 0.99`` and the directions of a
near-singular normal matrix (column-normalised Jacobian with singular value
ratio below 1e-3).  Minimiser: Levenberg-Marquardt (MINPACK through
``least_squares(method='lm')``); parameter values the robot file refuses, and
samples whose forward solve fails, give a large residual, so such a step is
rejected.  RMSE before calibration: the nominal robot with the best mocap
frame (fitted alone); after: the calibrated robot and frame.
No ROS import.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import optimize
from scipy.spatial.transform import Rotation

from ..geometry import hat, kabsch, left_jacobian_so3
from ..model import ConfigError, RobotConfig, parameter_keys as pk
from ._recordings import Recording
from ._sensitivities import RecordingModel

__all__ = ['CalibrationError', 'CalibrationResult', 'calibrate', 'CORRELATION_LIMIT',
           'SINGULAR_RATIO', 'PRIOR_SIGMA']

CORRELATION_LIMIT = 0.99
SINGULAR_RATIO = 1e-3
_PENALTY = 1e4           # weighted residual of a sample whose forward solve failed
_SIGMA_FLOOR = 1e-9
#: relative width (1 sigma) of the weak prior that keeps unobservable parameters at nominal
PRIOR_SIGMA = 0.2


#: A fit whose position and z-axis RMSEs both end more than this factor above the nominal
#: file's is refused (a file already right at the noise may end a little either side of it).
WORSE_THAN_NOMINAL = 1.1


class CalibrationError(ValueError):
    """The data cannot be calibrated (too few samples, failed solves, ...): one line."""


# ------------------------------------------------------------- rotations
# ---------------------------------------------------------------- result
@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate` (parameters in file units, see :mod:`.parameter_keys`)."""

    keys: list
    nominal: np.ndarray
    values: np.ndarray
    std_errors: np.ndarray
    ci95: np.ndarray                      # (k, 2)
    rotation: np.ndarray                  # base frame axes in the mocap frame
    translation_m: np.ndarray             # base frame origin in the mocap frame
    frame_std_errors: np.ndarray          # translation [m] (3), rotation vector [rad] (3)
    rmse_before_mm: float
    rmse_after_mm: float
    rmse_before_deg: float
    rmse_after_deg: float
    errors_before_mm: np.ndarray          # per sample
    errors_after_mm: np.ndarray
    angle_errors_before_deg: np.ndarray
    angle_errors_after_deg: np.ndarray
    samples: int
    sigma_position_m: float
    sigma_z_axis: float
    correlation: np.ndarray               # over keys + 6 frame parameters
    warnings: list
    config: RobotConfig
    converged: bool
    message: str
    nfev: int
    seconds: float
    unstable_samples: list = field(default_factory=list)

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        """Orientation of the base frame in the mocap frame (x, y, z, w)."""
        return Rotation.from_matrix(self.rotation).as_quat()

    def to_dict(self) -> dict:
        """JSON contract of ``bellow-ancf calibrate --json``."""
        return {
            'parameters': {k: {'value': float(v), 'std_error': float(s),
                               'ci95': [float(lo), float(hi)], 'nominal': float(n)}
                           for k, v, s, (lo, hi), n in zip(self.keys, self.values,
                                                           self.std_errors, self.ci95,
                                                           self.nominal)},
            'frame': {'translation_m': self.translation_m.tolist(),
                      'quaternion_xyzw': self.quaternion_xyzw.tolist(),
                      'translation_std_error_m': self.frame_std_errors[:3].tolist(),
                      'rotation_std_error_deg': np.degrees(self.frame_std_errors[3:]).tolist()},
            'rmse_before_mm': self.rmse_before_mm, 'rmse_after_mm': self.rmse_after_mm,
            'rmse_before_deg': self.rmse_before_deg, 'rmse_after_deg': self.rmse_after_deg,
            'samples': self.samples, 'sigma_position_mm': self.sigma_position_m * 1e3,
            'sigma_z_axis_deg': math.degrees(self.sigma_z_axis), 'warnings': list(self.warnings),
            'converged': bool(self.converged), 'message': self.message, 'nfev': self.nfev,
            'seconds': self.seconds, 'unstable_samples': list(self.unstable_samples),
        }


# ------------------------------------------------------------------ fit
class _Problem:
    """Weighted residual vector and Jacobian in the scaled variables ``[u, tau, w]``."""

    def __init__(self, cal: RecordingModel, rec: Recording, R0, length, prior=None):
        self.cal, self.R0, self.L = cal, R0, length
        self.prior = prior
        self.m = rec.positions_m
        self.n = Rotation.from_quat(rec.quaternions_xyzw).as_matrix()[:, :, 2]
        self.k = len(cal.keys)
        self.sig = np.array([1e-4, 1e-4 / length])
        self._cache = (None, None)

    def reweight(self, sig):
        """New noise levels (position, axis) of the weights; forget the last evaluation."""
        self.sig = sig
        self._cache = (None, None)

    def unpack(self, v):
        values = self.cal.nominal + v[: self.k] * self.cal.scales
        t = v[self.k:self.k + 3] * self.L
        w = v[self.k + 3:]
        return values, Rotation.from_rotvec(w).as_matrix() @ self.R0, t, w

    def _predict(self, v):
        key = v.tobytes()
        if self._cache[0] == key:
            return self._cache[1]
        values = self.unpack(v)[0]
        try:   # (one failed sample's penalty refuses the point: the rest need no solve)
            fws = self.cal.solve(values, give_up_after=1)
        except ConfigError:
            fws = [None] * len(self.m)
        self._cache = (key, fws)
        return fws

    def errors(self, v, fws=None):
        """Unweighted position and z-axis errors, (n, 3) each, in the mocap frame."""
        values, R, t, _ = self.unpack(v)
        pos, z = RecordingModel.pose_arrays(self._predict(v) if fws is None else fws)
        return pos @ R.T + t - self.m, z @ R.T - self.n

    def residual(self, v, fws=None):
        ep, ez = self.errors(v, fws)
        r = np.concatenate([ep / self.sig[0], ez / self.sig[1]], axis=1)
        r[~np.all(np.isfinite(r), axis=1)] = _PENALTY
        r = r.ravel()
        if self.prior is not None:
            r = np.concatenate([r, v[: self.k] * self.prior])
        return r

    def jacobian(self, v):
        fws = self._predict(v)
        values, R, _, w = self.unpack(v)
        pos, z = RecordingModel.pose_arrays(fws)
        dpos, dz = self.cal.sensitivities(values, fws)
        n = len(fws)
        J = np.zeros((n, 6, self.k + 6))
        J[:, :3, :self.k] = np.einsum('ab,nbk->nak', R, dpos) * self.cal.scales / self.sig[0]
        J[:, 3:, :self.k] = np.einsum('ab,nbk->nak', R, dz) * self.cal.scales / self.sig[1]
        J[:, :3, self.k:self.k + 3] = np.eye(3) * self.L / self.sig[0]
        Jl = left_jacobian_so3(w)
        J[:, :3, self.k + 3:] = -hat(pos @ R.T) @ Jl / self.sig[0]
        J[:, 3:, self.k + 3:] = -hat(z @ R.T) @ Jl / self.sig[1]
        J[~np.isfinite(J)] = 0.0
        J = J.reshape(6 * n, -1)
        if self.prior is not None:
            Jp = np.zeros((self.k, self.k + 6))
            Jp[:, :self.k] = np.diag(self.prior)
            J = np.vstack([J, Jp])
        return J


def _rmse(ep, ez, n):
    d = np.linalg.norm(ep, axis=1)
    zz = ez + n
    cos = np.clip(np.sum(zz * n, axis=1) / np.linalg.norm(zz, axis=1), -1.0, 1.0)
    ang = np.degrees(np.arccos(cos))
    return float(np.sqrt(np.mean(d**2)) * 1e3), float(np.sqrt(np.mean(ang**2))), d * 1e3, ang


def _separability(names, J, cov):
    """Warnings naming parameters the data cannot separate."""
    out = []
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sd, sd)
    corr[~np.isfinite(corr)] = 0.0
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if abs(corr[a, b]) > CORRELATION_LIMIT:
                out.append(f'{names[a]} and {names[b]} cannot be separated by the data '
                           f'(correlation {corr[a, b]:+.4f})')
    norms = np.linalg.norm(J, axis=0)
    for j in np.flatnonzero(norms == 0):
        out.append(f'{names[j]} has no influence on the measured poses')
    Jn = J[:, norms > 0] / norms[norms > 0]
    live = [nm for nm, nz in zip(names, norms > 0) if nz]
    _, s, Vt = np.linalg.svd(Jn, full_matrices=False)
    for i in np.flatnonzero(s < SINGULAR_RATIO * s[0]):
        involved = [live[j] for j in np.flatnonzero(np.abs(Vt[i]) > 0.3)]
        out.append('near-singular normal matrix (singular value ratio '
                   f'{s[i] / s[0]:.2g}): the data cannot separate ' + ', '.join(involved))
    return out, corr


def calibrate(cfg: RobotConfig, rec: Recording, keys: Sequence[str] | None = None,
              n_elements: int | None = None, max_nfev: int = 40, rounds: int = 3,
              prior_sigma: float | None = PRIOR_SIGMA) -> CalibrationResult:
    """Fit robot parameters ``keys`` (default :func:`parameter_keys.default_keys`) and the frame.

    ``prior_sigma``: relative width of the weak prior on every robot parameter
    (``(theta - theta_nominal)/(prior_sigma * |theta_nominal|)`` is one more
    residual), which holds directions the data cannot see at the nominal value;
    None: no prior.  ``max_nfev``: evaluation budget of each round.
    """
    start = time.perf_counter()
    keys = pk.default_keys(cfg.to_dict()) if keys is None else list(keys)
    cal = RecordingModel(cfg, keys, rec.pressures_pa, n_elements)
    n, k = len(rec), len(cal.keys)
    _check_data(cfg, rec, k)
    length = cfg.n_segments * cfg.l0 + sum(s.connector_height for s in cfg.segments)

    fws0 = cal.solve(cal.nominal)
    failed = [i for i, fw in enumerate(fws0) if fw is None]
    if failed:
        raise CalibrationError(f'the forward model of the nominal robot does not converge for '
                               f'sample {failed[0] + 1} (pressures '
                               f'{rec.pressures_pa[failed[0]] / 1e3} kPa)')
    pos0, z0 = RecordingModel.pose_arrays(fws0)
    n_meas = Rotation.from_quat(rec.quaternions_xyzw).as_matrix()[:, :, 2]
    R0, t0 = kabsch(pos0, rec.positions_m, z0, n_meas, length**2 * n)
    prob = _Problem(cal, rec, R0, length)
    v = np.zeros(k + 6)
    v[k:k + 3] = t0 / length

    # before: the nominal robot, the frame alone
    frame = np.zeros(k + 6, bool)
    frame[k:] = True

    def frame_fun(x):
        vv = v.copy()
        vv[frame] = x
        return prob.residual(vv, fws0)

    def frame_jac(x):
        vv = v.copy()
        vv[frame] = x
        return _frame_jacobian(prob, vv, fws0)
    sol = optimize.least_squares(frame_fun, v[frame], jac=frame_jac, method='lm')
    v[frame] = sol.x
    ep, ez = prob.errors(v, fws0)
    before = _rmse(ep, ez, prob.n)
    if prior_sigma is not None:   # weights of the prior residuals; none on zero nominal values
        prob.prior = np.where(cal.nominal != 0.0, 1.0 / prior_sigma, 0.0)

    nfev, sol = 0, None
    for _ in range(rounds):
        sol = optimize.least_squares(prob.residual, v, jac=prob.jacobian,
                                     method='lm', x_scale=1.0, max_nfev=max_nfev,
                                     ftol=1e-6, xtol=1e-5, gtol=1e-8)
        nfev += sol.nfev
        v = sol.x
        ep, ez = prob.errors(v)
        dof = max(1.0 - (k + 6) / (6.0 * n), 0.05)
        sig = np.array([math.sqrt(np.sum(ep**2) / (3 * n * dof)),
                        math.sqrt(np.sum(ez**2) / (2 * n * dof))])
        sig = np.maximum(sig, _SIGMA_FLOOR)
        change = np.max(np.abs(sig / prob.sig - 1.0))
        prob.reweight(sig)
        if change < 0.1:
            break
    res = _result(cal, prob, v, sol, before, nfev, time.perf_counter() - start)
    if (res.rmse_after_mm > WORSE_THAN_NOMINAL * res.rmse_before_mm
            and res.rmse_after_deg > WORSE_THAN_NOMINAL * res.rmse_before_deg):
        mass = '' if pk.MASS_SCALE in keys else f'a mass: fit {pk.MASS_SCALE} too; '
        raise CalibrationError(
            f'the fit ended farther from the recording than the nominal robot file (position '
            f'RMSE {res.rmse_before_mm:.3f} -> {res.rmse_after_mm:.3f} mm, z-axis '
            f'{res.rmse_before_deg:.3f} -> {res.rmse_after_deg:.3f} deg): the robot differs in '
            f'what the fitted keys {keys} cannot say ({mass}a length: fit its key)')
    return res


def _frame_jacobian(prob: _Problem, v, fws):
    """Jacobian of the residual with respect to the frame variables only (robot fixed)."""
    _, R, _, w = prob.unpack(v)
    pos, z = RecordingModel.pose_arrays(fws)
    n = len(fws)
    J = np.zeros((n, 6, 6))
    J[:, :3, :3] = np.eye(3) * prob.L / prob.sig[0]
    Jl = left_jacobian_so3(w)
    J[:, :3, 3:] = -hat(pos @ R.T) @ Jl / prob.sig[0]
    J[:, 3:, 3:] = -hat(z @ R.T) @ Jl / prob.sig[1]
    return J.reshape(6 * n, 6)


def _check_data(cfg: RobotConfig, rec: Recording, k: int) -> None:
    A = cfg.n_actuators_total
    if rec.n_actuators != A:
        raise CalibrationError(f'{rec.source}: {rec.n_actuators} pressures per sample, the robot '
                               f'{cfg.name} has {A} actuators')
    needed = k + 6
    if len(rec) < needed:
        raise CalibrationError(f'{rec.source}: {len(rec)} sample(s) for {needed} parameters '
                               f'({k} of '
                               f'the robot, 6 of the mocap frame); need at least {needed} samples')
    outside = (rec.pressures_pa < cfg.p_min - 1e-6) | (rec.pressures_pa > cfg.p_max + 1e-6)
    bad = np.flatnonzero(np.any(outside, axis=1))
    if bad.size:
        raise CalibrationError(f'{rec.source}: sample {bad[0] + 1} has pressures '
                               f'{np.round(rec.pressures_pa[bad[0]] / 1e3, 3).tolist()} kPa '
                               'outside '
                               f'the limits [{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa')
    finite = np.isfinite(rec.pressures_pa).all() and np.isfinite(rec.positions_m).all() \
        and np.isfinite(rec.quaternions_xyzw).all()
    if not finite:
        raise CalibrationError(f'{rec.source}: NaN or inf in the samples')


def _pinv_sym(A):
    """Pseudo-inverse of a symmetric positive semi-definite matrix."""
    w, V = np.linalg.eigh(A)
    keep = w > 1e-12 * max(w[-1], 1e-300)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


def _result(cal: RecordingModel, prob: _Problem, v, sol, before, nfev,
            seconds) -> CalibrationResult:
    k = prob.k
    n = len(prob.m)
    values, R, t, _ = prob.unpack(v)
    fws = cal.solve(values, check_stability=True)
    failed = sum(fw is None for fw in fws)
    if failed:
        raise CalibrationError(f'the forward model does not converge for {failed} '
                               'sample(s) at the fitted parameters')
    unstable = [i + 1 for i, fw in enumerate(fws) if fw is not None and fw.stable is False]
    ep, ez = prob.errors(v, fws)
    after = _rmse(ep, ez, prob.n)
    J = prob.jacobian(v)
    r = prob.residual(v)
    m = 6 * n
    Jd, rd = J[:m], r[:m]
    dof = max(m - (k + 6), 1)
    s2 = float(rd @ rd) / dof
    normal = Jd.T @ Jd / s2
    if prob.prior is not None:
        normal[:k, :k] += np.diag(prob.prior**2)
    cov = _pinv_sym(normal)
    scale = np.concatenate([cal.scales, np.full(3, prob.L), np.ones(3)])
    cov_phys = cov * np.outer(scale, scale)
    se = np.sqrt(np.clip(np.diag(cov_phys), 0, None))
    from scipy import stats   # (here: importing it costs a node process some 0.9 s at start)
    tq = stats.t.ppf(0.975, dof)
    names = list(cal.keys) + ['frame.x', 'frame.y', 'frame.z', 'frame.rx', 'frame.ry', 'frame.rz']
    warnings, corr = _separability(names, Jd, _pinv_sym(Jd.T @ Jd / s2))
    if unstable:
        warnings.append(f'the calibrated model is unstable (buckles) at sample(s) {unstable[:10]}')
    if not sol.success or sol.status == 0:
        warnings.append(f'least squares stopped: {sol.message}')
    ci = np.stack([values - tq * se[:k], values + tq * se[:k]], axis=1)
    return CalibrationResult(
        keys=list(cal.keys), nominal=cal.nominal.copy(), values=values, std_errors=se[:k], ci95=ci,
        rotation=R, translation_m=t, frame_std_errors=se[k:], rmse_before_mm=before[0],
        rmse_after_mm=after[0], rmse_before_deg=before[1], rmse_after_deg=after[1],
        errors_before_mm=before[2], errors_after_mm=after[2], angle_errors_before_deg=before[3],
        angle_errors_after_deg=after[3], samples=n, sigma_position_m=float(prob.sig[0]),
        sigma_z_axis=float(prob.sig[1]), correlation=corr, warnings=warnings,
        config=cal.config(values), converged=bool(sol.success and sol.status > 0),
        message=sol.message,
        nfev=nfev, seconds=seconds, unstable_samples=unstable)
