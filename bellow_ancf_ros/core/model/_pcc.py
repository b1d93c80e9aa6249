"""Piecewise-constant-curvature (PCC) kinematic model of the same robot.

The baseline the paper compares against (sections I and VI.D): every segment
is a circular arc, the actuators are parallel arcs at the pitch radius, and
no force enters the shape: gravity, payload and the bending stiffness are
ignored.  Only stage 1 (eq. 24, the same :class:`~.stage1.Stage1` as the ANCF
model) is shared, which turns pressures into actuator lengths
``l_i = lam_i * l0``.

Arc of one segment (``n_a >= 3`` actuators at angles ``theta_i`` and radius
``R`` in the segment's base frame, bending angle ``beta``, bending-plane
angle ``phi``, centre-line length ``s``)::

    l_i = s - R * beta * cos(theta_i - phi)

For evenly spaced actuators ``sum_i cos(theta_i) = sum_i sin(theta_i) = 0``, so
the three arc parameters follow in closed form (exact for any ``n_a``; for
``n_a > 3`` the least-squares arc)::

    s             = mean(l_i)
    beta cos(phi) = -2/(n_a R) * sum_i l_i cos(theta_i)
    beta sin(phi) = -2/(n_a R) * sum_i l_i sin(theta_i)

The segment's top plate sits at ``s/beta * ((1 - cos beta) cos phi,
(1 - cos beta) sin phi, sin beta)`` with rotation
``Rz(phi) Ry(beta) Rz(-phi)`` (no twist).  Segments are chained as in the
ANCF model (docs/model.md section 1): the next segment's base is the top plate
translated by the connector height ``h_c`` along its normal (actuator angles
``theta_0 + 2 pi (i-1)/n_a`` in that frame); the end effector is the last top
plate plus the tool offset, its x-axis towards actuator 1 of the last segment.

Inverse: for one segment the closed form of the arc through the target
(:func:`pcc_inverse`; the target must lie on an arc tangent to the base
axis, i.e. any point with ``z > 0``); for more segments (position and
z-axis target) a bounded least-squares problem on the stretches.  Pressures
are clipped to the hardware limits; ``reachable`` says whether the target is
met within them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ._config import RobotConfig
from ._stage1 import Stage1

__all__ = ['PccPose', 'PccModel', 'arc_parameters', 'arc_state', 'arc_transform']


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def arc_parameters(lengths, angles, radius):
    """``(s, beta, phi)`` of the arc through actuator lengths at ``angles`` / ``radius``."""
    lengths = np.asarray(lengths, dtype=float)
    angles = np.asarray(angles, dtype=float)
    n = lengths.size
    s = float(np.mean(lengths))
    bx = -2.0 / (n * radius) * float(np.dot(lengths, np.cos(angles)))
    by = -2.0 / (n * radius) * float(np.dot(lengths, np.sin(angles)))
    beta = float(np.hypot(bx, by))
    phi = float(np.arctan2(by, bx)) if beta > 0 else 0.0
    return s, beta, phi


def _sinc_terms(beta):
    """``sin(b)/b`` and ``(1 - cos b)/b`` without cancellation near 0."""
    if abs(beta) < 1e-4:
        b2 = beta * beta
        return 1.0 - b2 / 6.0 + b2 * b2 / 120.0, beta / 2.0 - beta * b2 / 24.0
    return np.sin(beta) / beta, (1.0 - np.cos(beta)) / beta


def arc_transform(s, beta, phi):
    """Position and rotation of the arc's end in its base frame."""
    sb, cb = _sinc_terms(beta)
    p = s * np.array([cb * np.cos(phi), cb * np.sin(phi), sb])
    R = _rz(phi) @ _ry(beta) @ _rz(-phi)
    return p, R


def arc_points(s, beta, phi, n_points):
    """Points along the arc's centre line (``n_points``, 3) in its base frame."""
    out = np.empty((n_points, 3))
    for i, t in enumerate(np.linspace(0.0, 1.0, n_points)):
        out[i] = arc_transform(s * t, beta * t, phi)[0]
    return out


def arc_state(model, lam):
    """A state ``x = [q, alpha]`` of the ANCF model (``model``) on the PCC arcs of ``lam``.

    The cold start of the forward solve: every segment the arc of its
    actuator lengths ``lam * l0`` (:func:`arc_parameters`), chained as in
    :meth:`PccModel.forward_stretch`; the nodes of every actuator on its
    parallel arc at the pitch radius, the gradients its tangent scaled by
    the arc's length over the natural length (1 for three actuators), the
    plates in the arc's frame at their fraction, the multipliers zero.  The
    constraints hold at the nodes, and the ANCF elements' cubic interpolation
    of the arc leaves a small residual at attachments inside an element;
    gravity and payload are what the Newton iteration then adds.
    """
    cfg = model.cfg
    lam = np.asarray(lam, dtype=float)
    q = np.zeros(model.nq)
    act = q[:model.nq_act].reshape(model.A, model.n_nodes, 6)
    pl = q[model.nq_act:].reshape(model.P, 12)
    frac = np.arange(model.n_nodes) / model.n
    p0, R0 = np.zeros(3), np.eye(3)
    for j, (seg, sl) in enumerate(zip(cfg.segments, cfg.actuator_slices)):
        if j > 0:
            p0 = p0 + seg.connector_height * R0[:, 2]
        s, beta, phi = arc_parameters(lam[sl] * cfg.l0, seg.actuator_angles, seg.pitch_radius)
        frames = [arc_transform(f * s, f * beta, phi) for f in frac]
        for a in range(sl.start, sl.stop):
            off = model.act_offset[a]
            length = s - float(np.hypot(off[0], off[1])) * beta * np.cos(
                model.act_angle[a] - phi)  # this actuator's arc
            stretch = length / (lam[a] * cfg.l0)
            for k, (dp, dR) in enumerate(frames):
                act[a, k, :3] = p0 + R0 @ (dp + dR @ off)
                act[a, k, 3:] = stretch * (R0 @ dR[:, 2])
        for k in model.seg_plates[j]:
            plate = model.plates[k]
            if plate["fraction"] > 0:
                f = plate["fraction"]
                dp, dR = arc_transform(f * s, f * beta, phi)
                pl[plate["unknown"], :3] = p0 + R0 @ dp
                pl[plate["unknown"], 3:] = (R0 @ dR).T.ravel()  # d1, d2, d3
        dp, dR = arc_transform(s, beta, phi)
        p0, R0 = p0 + R0 @ dp, R0 @ dR
    return np.concatenate([q, np.zeros(model.nc)])


@dataclass
class PccPose:
    """Result of the PCC forward kinematics (SI units)."""

    pressures_pa: np.ndarray
    stretch: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    arcs: list  # per segment (s, beta, phi)
    frames: list  # per segment (base position, base rotation)

    @property
    def z_axis(self):
        return self.rotation[:, 2]

    def backbone(self, n_points=20):
        """Centre line of every segment, concatenated: (m * n_points, 3)."""
        pts = []
        for (s, beta, phi), (p0, R0) in zip(self.arcs, self.frames):
            pts.append(p0 + arc_points(s, beta, phi, n_points) @ R0.T)
        return np.concatenate(pts)


class PccModel:
    """PCC kinematics of a :class:`~.config.RobotConfig` (gravity and payload ignored)."""

    def __init__(self, cfg: RobotConfig):
        self.cfg = cfg
        self.stage1 = Stage1.from_config(cfg)
        self.A = cfg.n_actuators_total

    # ---------------------------------------------------------- forward
    def forward_stretch(self, lam) -> PccPose:
        """Pose for given stage-1 stretches (one per actuator, segment by segment)."""
        cfg = self.cfg
        lam = np.asarray(lam, dtype=float).ravel()
        if lam.size != self.A:
            raise ValueError(f'expected {self.A} stretches, got {lam.size}')
        p, R = np.zeros(3), np.eye(3)
        arcs, frames = [], []
        for j, (seg, sl) in enumerate(zip(cfg.segments, cfg.actuator_slices)):
            if j > 0:
                p = p + seg.connector_height * R[:, 2]
            frames.append((p.copy(), R.copy()))
            s, beta, phi = arc_parameters(lam[sl] * cfg.l0, seg.actuator_angles, seg.pitch_radius)
            arcs.append((s, beta, phi))
            dp, dR = arc_transform(s, beta, phi)
            p = p + R @ dp
            R = R @ dR
        p = p + cfg.tool_length * R[:, 2]
        R = R @ _rz(cfg.segments[-1].theta0)
        return PccPose(self.stage1.pressure(lam), lam, p, R, arcs, frames)

    def forward(self, pressures_pa) -> PccPose:
        """Pose for given pressures [Pa] (limits not enforced here)."""
        p = np.asarray(pressures_pa, dtype=float).ravel()
        if p.size != self.A:
            raise ValueError(f'expected {self.A} pressures, got {p.size}')
        pose = self.forward_stretch(self.stage1.stretch(p))
        pose.pressures_pa = p.copy()
        return pose

    # ---------------------------------------------------------- inverse
    def inverse(self, position, z_axis=None, warm_lam=None):
        """Pressures for a target; returns ``(pressures_pa, reachable, PccPose)``.

        One segment: closed form (position only).  Two or more: bounded
        least squares on the stretches for position and z-axis.
        """
        cfg = self.cfg
        st = self.stage1
        lo, hi = st.lam_min, st.lam_max
        position = np.asarray(position, dtype=float).reshape(3)
        if cfg.n_segments == 1 and cfg.tool_length == 0.0:
            lam = self._inverse_one(position)
            lam_c = np.clip(lam, lo, hi)
            pose = self.forward_stretch(lam_c)
            ok = bool(np.all(np.abs(lam - lam_c) <= 1e-12)) and \
                np.linalg.norm(pose.position - position) <= 1e-9
            return np.clip(st.pressure(lam_c), cfg.p_min, cfg.p_max), ok, pose
        if cfg.n_segments > 1 and z_axis is None:
            raise ValueError('a robot with two or more segments needs a target z-axis')
        zt = None if z_axis is None else np.asarray(z_axis, float) / np.linalg.norm(z_axis)
        L = cfg.l0 * cfg.n_segments

        def fun(lam):
            pose = self.forward_stretch(lam)
            r = (pose.position - position) / L
            if zt is not None and cfg.n_segments > 1:
                r = np.concatenate([r, pose.z_axis - zt])
            return np.concatenate([r, 1e-4 * (lam - 1.0)])

        x0 = np.full(self.A, 1.0) if warm_lam is None else np.asarray(warm_lam, float)
        x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
        ls = least_squares(fun, x0, bounds=(np.full(self.A, lo), np.full(self.A, hi)),
                           xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=200)
        lam = ls.x
        pose = self.forward_stretch(lam)
        err = np.linalg.norm(pose.position - position)
        ok = err <= 1e-6 * L
        if zt is not None and cfg.n_segments > 1:
            ok = ok and np.arccos(np.clip(pose.z_axis @ zt, -1, 1)) <= 1e-5
        return np.clip(st.pressure(lam), cfg.p_min, cfg.p_max), bool(ok), pose

    def _inverse_one(self, position):
        """Closed-form arc through the target for one segment (unclipped stretches)."""
        seg = self.cfg.segments[0]
        x, y, z = position
        r = float(np.hypot(x, y))
        if z <= 0:
            raise ValueError('PCC: a one-segment arc tangent to the base axis cannot reach z <= 0')
        beta = 2.0 * np.arctan2(r, z)
        phi = float(np.arctan2(y, x)) if r > 0 else 0.0
        chord = np.hypot(r, z)
        # chord = 2 sin(beta/2)/kappa, s = beta/kappa
        s = chord * (beta / 2.0) / np.sin(beta / 2.0) if beta > 1e-12 else z
        lengths = s - seg.pitch_radius * beta * np.cos(seg.actuator_angles - phi)
        return lengths / self.cfg.l0
