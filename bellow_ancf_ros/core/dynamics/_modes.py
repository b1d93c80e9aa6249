"""Natural modes of an equilibrium: frequencies, damping ratios and mode shapes (docs/dynamics.md).

At an equilibrium of eq. (25) the linearised motion on the constraint
manifold is::

    M_r z'' + D_r z' + K_r z = 0,   q = q* + Z z,   C_q Z = 0,

with ``K_r = Z^T H Z`` the reduced Hessian of the Lagrangian (the matrix of
the stability test: elastic tangent, gravity through the multipliers, eq.
27), ``M_r = Z^T M Z`` and ``D_r = Z^T D Z`` (module ``_inertia``).  The
undamped natural frequencies solve ``K_r v = w^2 M_r v``; the damped ones
and the damping ratios ``zeta = -Re(s)/|s|`` come from the quadratic
eigenvalue problem ``(s^2 M_r + s D_r + K_r) v = 0``, solved as a
first-order pencil.  The eigenvalues do not depend on the coordinates, so the
analysis runs in the static (stretched) coordinates of the equilibrium,
where ``M_s = T M T`` and ``D_s = T D T``.

The robot is symmetric about its axis: lateral bending modes come in
pairs of equal frequency.  Inside such a pair any combination is a mode;
the pair is turned so that the end effector's motions come as close as they can
to the base x and y axes (orthogonal Procrustes), which makes them
reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from ..linalg import one_thread_call
from ..model import RobotModel, TipLoad
from ._inertia import Inertia

__all__ = ["Mode", "ModalAnalysis", "ModalError", "ReducedSystem", "natural_modes",
           "reduced_system"]

_CLUSTER_RTOL = 1e-6
#: Up to this many modes the damped eigenvalues come from Newton's method on the quadratic
#: eigenproblem (a few complex solves of the reduced size, milliseconds), beyond it from the
#: dense first-order pencil (an eigenvalue problem of twice the size: 0.1 s for two segments).
_NEWTON_MODES = 2


# The dense linear algebra here goes through numpy, whose LAPACK calls release the
# interpreter; scipy.linalg's hold it for the whole call (``eig`` of the pencil 130-180 ms,
# the null space's SVD 10 ms for two segments), and a node computes modes in a thread
# beside its control thread: a modal analysis stalled the inverse node's commands by up to
# 0.18 s (tests/core/dynamics/test_modes.py measures a thread's wake-ups beside it).
def _pencil(K, M, D):
    """Eigenvalues and displacement rows of the eigenvectors of ``s^2 M + s D + K``.

    The first-order form ``[[0, I], [-M^-1 K, -M^-1 D]]`` (``M`` positive
    definite): the pencil's eigenpairs, through numpy's ``eig``.
    """
    n = K.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
    s, X = np.linalg.eig(A)
    return s, X[:n]


def _generalized_eigh(K, M):
    """``K V = M V diag(w2)``, ``V^T M V = I``, ascending (Cholesky of ``M``, numpy's ``eigh``).

    Raises ``LinAlgError`` when ``M`` is not positive definite.
    """
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    C = Li @ K @ Li.T
    w2, Y = np.linalg.eigh(0.5 * (C + C.T))
    return w2, Li.T @ Y


def _damped_by_eig(Kr, Mr, Dr, V):
    """Damped eigenvalues (Im >= 0) matched to the undamped shapes ``V`` (M-weighted MAC)."""
    s, X = _pencil(Kr, Mr, Dr)
    used = np.zeros(len(s), bool)
    out = []
    for m in range(V.shape[1]):
        v = V[:, m]
        mv = Mr @ v
        num = np.abs(X.T @ mv) ** 2
        den = np.real(np.einsum("ij,ij->j", X.conj(), Mr @ X)) * (v @ mv)
        mac = np.where((s.imag >= -1e-12 * np.abs(s)) & ~used & np.isfinite(s),
                       num / np.maximum(den, 1e-300), -1.0)
        c = int(np.argmax(mac))
        used[c] = True   # (polished by Newton: the first-order form's eig loses digits)
        polished = _damped_newton(Kr, Mr, Dr, 0.0, v, start=(s[c], X[:, c]))
        out.append(s[c] if polished is None else polished)
    return out


def _damped_newton(Kr, Mr, Dr, w, v, iters: int = 12, start=None):
    """The damped eigenvalue near the undamped mode ``(w, v)``, or None if Newton fails.

    Newton's method on ``T(s) x = 0``, ``T(s) = s^2 M + s D + K``, bordered
    by the normalisation ``v^T M x = 1``; the start is the proportional-damping
    estimate ``zeta = v^T D v / (2 w)`` (unit modal mass), or ``start``
    (``(s, x)``: an eigenpair of the pencil to polish).  Quadratic
    convergence: 3-5 solves of the reduced size.
    """
    n = Kr.shape[0]
    c = Mr @ v
    if start is not None:
        s, x = complex(start[0]), np.asarray(start[1], complex)
        if not abs(c @ x) > 0:
            return None
        x = x / (c @ x)
    else:
        z0 = float(v @ Dr @ v) / (2 * w)
        if not 0 <= z0 < 1:
            return None
        s = complex(-z0 * w, w * np.sqrt(1 - z0 * z0))
        x = v.astype(complex) / (c @ v)
    J = np.zeros((n + 1, n + 1), complex)
    J[n, :n] = c
    for _ in range(iters):
        T = s * s * Mr + s * Dr + Kr
        J[:n, :n] = T
        J[:n, n] = (2 * s * Mr + Dr) @ x
        r = np.concatenate([T @ x, [c @ x - 1.0]])
        try:
            d = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError:
            return None
        x, s = x + d[:n], s + d[n]
        if abs(d[n]) <= 1e-10 * abs(s):   # quadratic: the last step left ~1e-20
            return s if s.imag >= 0 and np.all(np.isfinite(x)) else None
    return None


class ModalError(ValueError):
    """An equilibrium whose modes cannot be computed (unstable, not converged, no inertia)."""


@dataclass
class Mode:
    """One natural mode.

    ``frequency_hz``: undamped natural frequency; ``damped_frequency_hz`` and
    ``damping_ratio`` from the damped problem (``damped_frequency_hz`` is 0
    for an overdamped mode); ``direction``: unit vector of the end
    effector's motion in the base frame; ``tip_rotation``: the motion of the
    end effector's z-axis per metre of tip motion along ``direction``;
    ``shape``: the static-coordinate mode shape (``nq``), scaled to 1 mm of
    tip motion (unit modal mass if the tip does not move).
    """

    frequency_hz: float
    damped_frequency_hz: float
    damping_ratio: float
    direction: np.ndarray
    tip_rotation: np.ndarray
    shape: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        return {"frequency_hz": float(self.frequency_hz),
                "damped_frequency_hz": float(self.damped_frequency_hz),
                "damping_ratio": float(self.damping_ratio),
                "direction": [float(v) for v in self.direction]}


@dataclass
class ModalAnalysis:
    """The lowest modes of one equilibrium (``modes``, lowest first)."""

    model: RobotModel
    q: np.ndarray
    stretch: np.ndarray
    load: TipLoad
    damping_time_s: float
    mass_damping_per_s: float
    modes: list

    @property
    def first(self) -> Mode:
        return self.modes[0]

    def backbones(self, mode: int, amplitude_m: float = 0.01, n_points: int = 20):
        """Backbones ``(A, n_points, 3)`` of the equilibrium moved along a mode.

        ``amplitude_m``: tip displacement of the drawn shape (the shape is
        linear: this only scales the picture).
        """
        sh = self.modes[mode].shape * (amplitude_m / 1e-3)
        return self.model.backbones(self.q + sh, self.stretch, n_points)

    def to_dict(self) -> dict:
        return {"modes": [m.to_dict() for m in self.modes],
                "payload_kg": float(self.load.payload_kg),
                "tip_force_n": [float(f) for f in self.load.force_n],
                "damping_time_s": self.damping_time_s,
                "mass_damping_per_s": self.mass_damping_per_s}


def _tip_rows(model):
    """Rows mapping static coordinates to the tip's position and its z-axis (both linear)."""
    pd = model.plate_dofs[model.ee_plate]
    P = np.zeros((3, model.nq))
    P[np.arange(3), pd[0:3]] = 1.0
    P[np.arange(3), pd[9:12]] = model.cfg.tool_length
    Zr = np.zeros((3, model.nq))
    Zr[np.arange(3), pd[9:12]] = 1.0
    return P, Zr


@one_thread_call
def natural_modes(fw, n_modes: int = 6, inertia: Inertia | None = None,
                  damping_time_s: float | None = None,
                  mass_damping_per_s: float | None = None) -> ModalAnalysis:
    """Natural frequencies, damping ratios and mode shapes of an equilibrium.

    Parameters
    ----------
    fw : ForwardResult
        A converged, stable equilibrium (:func:`~bellow_ancf_ros.core.solve_forward`,
        or the ``forward`` of an inverse result), any segment count, with its
        payload and tip force.
    n_modes : how many of the lowest modes to return.
    inertia : an :class:`Inertia` of ``fw.model`` to reuse (else one is made).
    damping_time_s, mass_damping_per_s : override the robot file's damping.

    Returns
    -------
    ModalAnalysis

    Raises
    ------
    ModalError
        The equilibrium did not converge, is not stable (a non-positive
        reduced stiffness), or the mass is not positive on the constraints'
        tangent space.
    """
    red = reduced_system(fw, inertia, damping_time_s, mass_damping_per_s)
    model, Kr, Mr, w2, V = red.model, red.K, red.M, red.w2, red.V
    Dr = red.damping(red.damping_time, red.mass_damping)
    k = min(int(n_modes), len(w2))
    w = np.sqrt(w2[:k])
    V = V[:, :k]
    P, Zrow = _tip_rows(model)
    Phi = red.Z @ V  # static-coordinate shapes, unit modal mass
    # turn degenerate clusters (the x/y pairs) to the tip's principal directions
    i = 0
    while i < k:
        j = i + 1
        while j < k and abs(w[j] - w[i]) <= _CLUSTER_RTOL * w[i]:
            j += 1
        if j - i > 1:  # orthogonal Procrustes: tip motions as close as may be to x, y, z
            tip = P @ Phi[:, i:j]
            U, _, Vt = np.linalg.svd(tip.T @ np.eye(3)[:, :j - i])
            R = U @ Vt
            Phi[:, i:j] = Phi[:, i:j] @ R
            V[:, i:j] = V[:, i:j] @ R
        i = j
    # damped modes: (s^2 Mr + s Dr + Kr) x = 0; a few: Newton from each undamped one
    damped = [_damped_newton(Kr, Mr, Dr, w[m], V[:, m]) for m in range(k)] \
        if k <= _NEWTON_MODES else None
    if damped is None or any(d is None for d in damped):
        damped = _damped_by_eig(Kr, Mr, Dr, V[:, :k])
    modes = []
    for m in range(k):
        sc = damped[m]
        zeta = float(-sc.real / abs(sc)) if abs(sc) > 0 else 1.0
        tip = P @ Phi[:, m]
        amp = float(np.linalg.norm(tip))
        if amp > 1e-12 * np.linalg.norm(Phi[:, m]):
            d = tip / amp
            sgn = 1.0 if d[np.argmax(np.abs(d))] >= 0 else -1.0
            d = sgn * d
            shape = Phi[:, m] * (sgn * 1e-3 / amp)
            rot = Zrow @ shape / 1e-3
        else:
            d, shape, rot = np.zeros(3), Phi[:, m].copy(), np.zeros(3)
        modes.append(Mode(frequency_hz=float(w[m] / (2 * np.pi)),
                          damped_frequency_hz=float(abs(sc.imag) / (2 * np.pi)),
                          damping_ratio=zeta, direction=d, tip_rotation=rot, shape=shape))
    return ModalAnalysis(model=model, q=fw.q.copy(), stretch=red.stretch.copy(), load=red.load,
                         damping_time_s=red.damping_time,
                         mass_damping_per_s=red.mass_damping, modes=modes)


@dataclass
class ReducedSystem:
    """The linearised robot on the constraints' tangent space (``q = q* + Z z``).

    ``K``, ``M``: reduced stiffness and mass; ``D_kv``: the Kelvin-Voigt
    damping per second of retardation time; ``w2, V``: the undamped
    eigenpairs (``K V = M V diag(w2)``, unit modal mass).
    """

    model: RobotModel
    stretch: np.ndarray
    load: TipLoad
    Z: np.ndarray
    K: np.ndarray
    M: np.ndarray
    D_kv: np.ndarray
    w2: np.ndarray
    V: np.ndarray
    damping_time: float
    mass_damping: float

    def damping(self, damping_time_s: float, mass_damping_per_s: float = 0.0) -> np.ndarray:
        """Reduced damping matrix for a retardation time and an air damping."""
        return damping_time_s * self.D_kv + mass_damping_per_s * self.M

    @one_thread_call
    def damped_first(self, damping_time_s: float, mass_damping_per_s: float = 0.0):
        """Damped frequency [Hz] and damping ratio of the first mode for another damping."""
        D = self.damping(damping_time_s, mass_damping_per_s)
        sc = _damped_by_eig(self.K, self.M, D, self.V[:, :1])[0]
        return float(abs(sc.imag) / (2 * np.pi)), float(-sc.real / abs(sc))


def _null_space(C: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the null space of the constraint Jacobian ``C``.

    LAPACK's divide-and-conquer SVD (``gesdd``, numpy's, which releases the
    interpreter) now and then fails to converge on a finite matrix (once in
    a 200-robot run of the robot family's closed loops, from the mode
    check); the QR-iteration SVD (``gesvd``, scipy's) is then used.  A
    Jacobian that is not finite, or that neither resolves, raises
    :class:`ModalError`.
    """
    if not np.all(np.isfinite(C)):
        raise ModalError("the constraint Jacobian is not finite: no modes")
    try:   # (as scipy.linalg.null_space: the singular values below max(shape) eps s_max)
        _, sv, vh = np.linalg.svd(C, full_matrices=True)
        rank = int(np.sum(sv > max(C.shape) * np.finfo(float).eps * (sv[0] if sv.size else 0)))
        return vh[rank:].T.conj()
    except np.linalg.LinAlgError:
        try:
            return sla.null_space(C, lapack_driver="gesvd")
        except np.linalg.LinAlgError as exc:
            raise ModalError(f"the constraints' null space: {exc}") from exc


@one_thread_call
def reduced_system(fw, inertia: Inertia | None = None, damping_time_s: float | None = None,
                   mass_damping_per_s: float | None = None) -> ReducedSystem:
    """Reduce stiffness, mass and damping of the equilibrium ``fw`` (module docstring).

    Raises :class:`ModalError` (see :func:`natural_modes`).
    """
    model = fw.model
    if not fw.converged:
        raise ModalError("the equilibrium did not converge: no modes")
    inertia = inertia or Inertia(model, damping_time_s, mass_damping_per_s)
    beta = inertia.damping_time if damping_time_s is None else float(damping_time_s)
    alpha = inertia.mass_damping if mass_damping_per_s is None else float(mass_damping_per_s)
    lam = np.asarray(fw.stretch, dtype=float)
    load = fw.load
    nq = model.nq
    ev = model.evaluate(fw.x, lam, 1.0, load, jacobian=True)
    J = ev.jacobian.toarray()
    H = 0.5 * (J[:nq, :nq] + J[:nq, :nq].T)
    Z = _null_space(J[nq:, :nq])
    T = inertia.scale(lam)
    M = inertia.mass_matrix(load).toarray() * T[:, None] * T[None, :]
    # Kelvin-Voigt per unit retardation time, static coordinates: the element blocks
    ed = model.elem_dofs
    blocks = Inertia(model, 1.0, 0.0).damping_blocks(inertia.to_material(fw.q, lam), lam)
    Dkv = np.zeros((nq, nq))
    np.add.at(Dkv, (np.repeat(ed, 12, axis=1).ravel(), np.tile(ed, (1, 12)).ravel()),
              blocks.ravel())
    Kr, Mr, Dr = (0.5 * (A + A.T) for A in (Z.T @ H @ Z, Z.T @ M @ Z, Z.T @ Dkv @ Z))
    try:
        w2, V = _generalized_eigh(Kr, Mr)
    except np.linalg.LinAlgError as exc:
        raise ModalError("the mass is not positive definite on the constraints' tangent "
                         "space (massless parts?)") from exc
    if w2[0] <= 0.0:
        raise ModalError(f"the equilibrium is not stable (smallest reduced stiffness "
                         f"eigenvalue {w2[0]:.3g}): no oscillation about it")
    return ReducedSystem(model=model, stretch=lam, load=load, Z=Z, K=Kr, M=Mr, D_kv=Dr, w2=w2,
                         V=V, damping_time=beta, mass_damping=alpha)
