"""Rotations, quaternions and angles: the one copy the core, the nodes and the demos use.

Quaternions are in ROS order ``(x, y, z, w)`` everywhere in this package
(``geometry_msgs/Quaternion``, scipy's ``Rotation.as_quat``), ``w`` the
scalar part.  A rotation matrix's columns are the rotated frame's x, y and z
axes in the reference frame; the end effector's z-axis is the third column.
Rotation vectors are axis times angle [rad].
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

__all__ = [
    "QUATERNION_MIN_NORM", "angle_between", "hat", "kabsch", "left_jacobian_so3",
    "quaternion_from_rotation", "quaternion_from_z_axis", "quaternion_mean",
    "quaternion_to_rotation", "rotation_between", "rotation_from_vector", "rotation_vector",
    "rotation_z",
    "unit_quaternion", "z_axis_from_quaternion",
]

#: A quaternion shorter than this is refused: it names no rotation (a zeroed message).
QUATERNION_MIN_NORM = 1e-6


def unit_quaternion(q: Sequence[float]) -> np.ndarray:
    """``q`` (x, y, z, w) normalised; ValueError when it has not 4 finite components or is ~0."""
    arr = np.array(q, dtype=float).ravel()
    if arr.size != 4:
        raise ValueError(f'a quaternion has 4 components, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise ValueError('quaternion has NaN or inf components')
    nrm = float(np.linalg.norm(arr))
    if not math.isfinite(nrm) or nrm < QUATERNION_MIN_NORM:
        raise ValueError(f'quaternion cannot be normalised (norm {nrm:.3g})')
    return arr / nrm


def quaternion_to_rotation(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix (columns = rotated x, y, z axes) of a quaternion ``(x, y, z, w)``.

    The quaternion is normalised; zero, NaN or inf ones raise ValueError.
    """
    x, y, z, w = unit_quaternion(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def z_axis_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """The local z-axis (third column of the rotation) of ``(x, y, z, w)``, unit length."""
    x, y, z, w = unit_quaternion(q)
    v = np.array([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])
    return v / np.linalg.norm(v)


def quaternion_from_rotation(R: Any) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` (``w >= 0``) of a rotation matrix (Shepperd's method)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = \
        np.asarray(R, dtype=float).reshape(3, 3).tolist()
    if not math.isfinite(m00 + m01 + m02 + m10 + m11 + m12 + m20 + m21 + m22):
        raise ValueError('rotation matrix has NaN or inf entries')
    tr = m00 + m11 + m22
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(max(1.0 + m00 - m11 - m22, 1e-300))
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(max(1.0 + m11 - m00 - m22, 1e-300))
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(max(1.0 + m22 - m00 - m11, 1e-300))
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[3] < 0:
        n = -n
    return np.array([q[0] / n, q[1] / n, q[2] / n, q[3] / n])


def quaternion_from_z_axis(z_axis: Any) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` of the smallest rotation taking base ``z`` onto ``z_axis``."""
    v = np.asarray(z_axis, dtype=float).reshape(3)
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n < 1e-12:
        raise ValueError('z-axis must be a finite non-zero vector')
    v = v / n
    c = float(v[2])
    if c < -1.0 + 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])  # half turn about x
    # rotation axis e_z x v, angle acos(c): q = (sin(a/2) axis, cos(a/2))
    w = math.sqrt(0.5 * (1.0 + c))
    s = 0.5 / w
    return np.array([-v[1] * s, v[0] * s, 0.0, w])


def quaternion_mean(q: np.ndarray) -> np.ndarray:
    """Mean of nearby unit quaternions (rows; signs aligned to the first), normalised."""
    q = np.asarray(q, dtype=float)
    signs = np.where(q @ q[0] < 0.0, -1.0, 1.0)
    m = (q * signs[:, None]).mean(axis=0)
    return m / np.linalg.norm(m)


def angle_between(a: Any, b: Any):
    """Angle between vectors [rad], robust near 0 and pi; rows of ``(..., 3)`` give an array."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == b.shape == (3,):   # (one pair, as the control loop asks: no array calls)
        ax, ay, az = a.tolist()
        bx, by, bz = b.tolist()
        cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)
    ang = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
    return float(ang) if np.ndim(ang) == 0 else ang


def hat(v: np.ndarray) -> np.ndarray:
    """Skew matrices ``[v]x`` of vectors ``(..., 3)``: ``[v]x u`` is the cross product."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def rotation_from_vector(v: Any) -> np.ndarray:
    """Rotation matrix of the rotation vector ``v`` (axis times angle, Rodrigues' formula).

    Written with plain floats: called at every motion-capture sample of the
    simulated robot (twice), where numpy's per-call cost of the matrix form
    (``I + sin K + (1 - cos) K^2``) was five times the arithmetic.
    """
    x, y, z = np.asarray(v, dtype=float).reshape(3).tolist()
    theta = math.sqrt(x * x + y * y + z * z)
    if theta < 1e-15:
        return np.eye(3)
    s, c = math.sin(theta), 1.0 - math.cos(theta)
    x, y, z = x / theta, y / theta, z / theta
    return np.array([[1.0 - c * (y * y + z * z), c * x * y - s * z, c * x * z + s * y],
                     [c * x * y + s * z, 1.0 - c * (x * x + z * z), c * y * z - s * x],
                     [c * x * z - s * y, c * y * z + s * x, 1.0 - c * (x * x + y * y)]])


def rotation_vector(R: Any) -> np.ndarray:
    """Rotation vector (axis times angle in ``[0, pi]``) of a rotation matrix.

    The inverse of :func:`rotation_from_vector`, through
    :func:`quaternion_from_rotation` (``w >= 0``): ``2 atan2(|v|, w) v / |v|``.
    """
    x, y, z, w = quaternion_from_rotation(R)
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-300:
        return np.zeros(3)
    return np.array([x, y, z]) * (2.0 * math.atan2(s, w) / s)


def rotation_between(z_from: Any, z_to: Any) -> np.ndarray:
    """Rotation vector (axis * angle, rad) of the smallest rotation ``z_from`` -> ``z_to``."""
    ax, ay, az = np.asarray(z_from, dtype=float).reshape(3).tolist()
    bx, by, bz = np.asarray(z_to, dtype=float).reshape(3).tolist()
    n = math.sqrt(ax * ax + ay * ay + az * az) * math.sqrt(bx * bx + by * by + bz * bz)
    if not n > 0.0:   # (a zero vector has no direction: NaN, as numpy's division gave it)
        return np.full(3, math.nan)
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx   # (a x b, scalar:
    s = math.sqrt(cx * cx + cy * cy + cz * cz) / n     # numpy's cross costs 20 times more)
    angle = math.atan2(s, (ax * bx + ay * by + az * bz) / n)
    if s < 1e-15:
        return np.zeros(3)
    return np.array([cx, cy, cz]) * (angle / (s * n))


def rotation_z(theta):
    """Rotation matrix about z by ``theta`` [rad]."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def left_jacobian_so3(w: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3): ``exp([w + d]) = exp([J_l(w) d]) exp([w])`` to first order."""
    w = np.asarray(w, dtype=float)
    th = float(np.linalg.norm(w))
    W = hat(w)
    if th < 1e-8:
        return np.eye(3) + 0.5 * W
    return np.eye(3) + (1 - math.cos(th)) / th**2 * W + (th - math.sin(th)) / th**3 * (W @ W)


def kabsch(a: np.ndarray, b: np.ndarray, dirs_a=None, dirs_b=None, dir_weight: float = 0.0):
    """Rotation ``R`` and translation ``t`` minimising ``sum |R a_i + t - b_i|^2``.

    Optional unit directions add ``dir_weight * sum |R u_i - v_i|^2`` (no translation).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    ca, cb = a.mean(0), b.mean(0)
    H = (a - ca).T @ (b - cb)
    if dirs_a is not None:
        H = H + dir_weight * np.asarray(dirs_a, float).T @ np.asarray(dirs_b, float)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca
