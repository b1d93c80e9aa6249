"""core.geometry: quaternions (x, y, z, w), rotations, angles: known values and round trips."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import geometry


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_z_axis_from_quaternion_known_values():
    np.testing.assert_allclose(geometry.z_axis_from_quaternion([0, 0, 0, 1]), [0, 0, 1])
    s = math.sqrt(0.5)
    # +90 deg about x: z -> -y ; +90 deg about y: z -> +x
    np.testing.assert_allclose(geometry.z_axis_from_quaternion([s, 0, 0, s]), [0, -1, 0],
                               atol=1e-15)
    np.testing.assert_allclose(geometry.z_axis_from_quaternion([0, s, 0, s]), [1, 0, 0],
                               atol=1e-15)
    # rotation about z does not move the z-axis; scaling is normalised away
    np.testing.assert_allclose(geometry.z_axis_from_quaternion([0, 0, 5 * s, 5 * s]), [0, 0, 1],
                               atol=1e-15)


@pytest.mark.parametrize('q,match', [
    ([0, 0, 0, 0], 'normalised'),
    ([1e-9, 0, 0, 0], 'normalised'),
    ([math.nan, 0, 0, 1], 'NaN or inf'),
    ([0, math.inf, 0, 1], 'NaN or inf'),
    ([0, 0, 1], '4 components'),
])
def test_bad_quaternions_refused(q, match):
    with pytest.raises(ValueError, match=match):
        geometry.z_axis_from_quaternion(q)
    with pytest.raises(ValueError):
        geometry.quaternion_to_rotation(q)


def test_quaternion_rotation_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(200):
        R = _rot(rng.normal(size=3), rng.uniform(-math.pi, math.pi))
        q = geometry.quaternion_from_rotation(R)
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(geometry.quaternion_to_rotation(q), R, atol=1e-12)
        np.testing.assert_allclose(geometry.z_axis_from_quaternion(q), R[:, 2], atol=1e-12)
    # the near-half-turn branches
    for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]):
        R = _rot(axis, math.pi)
        back = geometry.quaternion_to_rotation(geometry.quaternion_from_rotation(R))
        np.testing.assert_allclose(back, R, atol=1e-12)


def test_quaternion_from_z_axis():
    rng = np.random.default_rng(1)
    for z in list(rng.normal(size=(100, 3))) + [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 0, 1e-3]]:
        z = np.asarray(z, float)
        q = geometry.quaternion_from_z_axis(z)
        np.testing.assert_allclose(geometry.z_axis_from_quaternion(q), z / np.linalg.norm(z),
                                   atol=1e-12)
    # smallest rotation: no twist about z, i.e. the rotation axis is horizontal
    q = geometry.quaternion_from_z_axis([math.sin(0.3), 0, math.cos(0.3)])
    assert q[2] == 0.0
    assert geometry.angle_between(geometry.quaternion_to_rotation(q)[:, 1], [0, 1, 0]) < 1e-12
    with pytest.raises(ValueError):
        geometry.quaternion_from_z_axis([0, 0, 0])


def test_angle_between():
    assert geometry.angle_between([0, 0, 1], [0, 0, 2]) == 0.0
    assert geometry.angle_between([0, 0, 1], [0, 1, 0]) == pytest.approx(math.pi / 2)
    assert geometry.angle_between([0, 0, 1], [0, 0, -1]) == pytest.approx(math.pi)
    assert geometry.angle_between([1, 0, 0], [1, 1e-9, 0]) == pytest.approx(1e-9, rel=1e-6)


# ------------------------------------------------------------------ targets


def test_angle_between_rows_and_scalars_agree():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    rows = geometry.angle_between(a, b)
    assert rows.shape == (5,)
    for k in range(5):
        cos = a[k] @ b[k] / np.linalg.norm(a[k]) / np.linalg.norm(b[k])
        assert rows[k] == pytest.approx(math.acos(cos), abs=1e-12)
        assert geometry.angle_between(a[k], b[k]) == rows[k]


def test_hat_is_the_cross_product_and_rotation_vector_round_trip():
    rng = np.random.default_rng(2)
    v, u = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(geometry.hat(v) @ u, np.cross(v, u), atol=1e-15)
    a, b = rng.normal(size=3), rng.normal(size=3)
    r = geometry.rotation_between(a, b)
    np.testing.assert_allclose(geometry.rotation_from_vector(r) @ (a / np.linalg.norm(a)),
                               b / np.linalg.norm(b), atol=1e-12)
    assert np.linalg.norm(r) == pytest.approx(geometry.angle_between(a, b), abs=1e-12)
    np.testing.assert_array_equal(geometry.rotation_between(a, 3.0 * a), np.zeros(3))
    assert np.isnan(geometry.rotation_between(np.zeros(3), b)).all()
    tiny = geometry.rotation_between([0.0, 0.0, 2.0], [1e-9, 0.0, 1.0])   # (not lost to rounding)
    np.testing.assert_allclose(tiny, [0.0, 1e-9, 0.0], rtol=1e-6, atol=0)


def test_quaternion_mean_of_sign_flipped_copies():
    q = geometry.quaternion_from_z_axis([0.1, 0.2, 1.0])
    mean = geometry.quaternion_mean(np.array([q, -q, q]))
    np.testing.assert_allclose(abs(mean @ q), 1.0, atol=1e-12)


def test_rotation_z_turns_x_onto_y():
    np.testing.assert_allclose(geometry.rotation_z(math.pi / 2) @ [1, 0, 0], [0, 1, 0],
                               atol=1e-15)


def test_rotation_vector_inverts_rotation_from_vector_and_agrees_with_scipy():
    """Log map: round trips from tiny turns to half turns, scipy's ``as_rotvec`` the reference."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(5)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate([[0.0, 1e-12, 1e-8, 1e-4, math.pi - 1e-9, math.pi],
                             rng.uniform(0.0, math.pi, 194)])
    for axis, angle in zip(axes, angles):
        R = geometry.rotation_from_vector(axis * angle)
        np.testing.assert_allclose(R, Rotation.from_rotvec(axis * angle).as_matrix(),
                                   atol=1e-15)
        v = geometry.rotation_vector(R)
        np.testing.assert_allclose(geometry.rotation_from_vector(v), R, atol=1e-12)
        assert np.linalg.norm(v) == pytest.approx(angle, abs=1e-9)
        ref = Rotation.from_matrix(R).as_rotvec()
        if angle < math.pi - 1e-6:   # (at a half turn v and -v are the same rotation)
            np.testing.assert_allclose(v, ref, atol=1e-12)
