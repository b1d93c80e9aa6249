"""Mass and damping of the dynamic model (docs/dynamics.md): rigid motions, gravity, damping."""

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_forward
from bellow_ancf_ros.core.dynamics import Inertia
from bellow_ancf_ros.core.dynamics._kernels import dynamic_rhs


def _rigid(model, q_static, lam, omega=None, velocity=None):
    """Material-coordinate velocity of a rigid motion of the whole robot."""
    inertia = Inertia(model)
    q = inertia.to_material(q_static, lam)
    v = np.zeros(model.nq)
    pos = np.zeros(model.nq, bool)
    act = np.zeros((model.A, model.n_nodes, 6), bool)
    act[..., :3] = True
    pos[:model.nq_act] = act.ravel()
    pl = np.zeros((model.P, 12), bool)
    pl[:, :3] = True
    pos[model.nq_act:] = pl.ravel()
    if velocity is not None:
        v.reshape(-1, 3)[pos.reshape(-1, 3)[:, 0]] = velocity
    if omega is not None:  # every 3-vector (positions, slopes, plate axes) turns: w x r
        v = np.cross(np.broadcast_to(omega, (model.nq // 3, 3)), q.reshape(-1, 3)).ravel()
    return inertia, q, v


@pytest.mark.parametrize("robot", ["one", "two", "three"])
@pytest.mark.parametrize("payload", [0.0, 0.05])
def test_translation_kinetic_energy_is_total_mass(robot, payload, request):
    model = request.getfixturevalue(robot)
    lam = np.full(model.A, 1.07)
    inertia, q, v = _rigid(model, model.straight_state(lam)[:model.nq], lam,
                           velocity=np.array([0.3, -0.2, 0.5]))
    cfg = model.cfg
    mass = cfg.rho0 * cfg.l0 * model.A + payload + sum(
        s.top_plate_mass + len(s.plate_fractions) * s.constraint_plate_mass + s.connector_mass
        for s in cfg.segments)
    assert inertia.total_mass(payload) == pytest.approx(mass, rel=1e-14)
    assert inertia.kinetic_energy(v, payload) == pytest.approx(0.5 * mass * 0.38, rel=1e-12)


@pytest.mark.parametrize("robot", ["one", "two"])
def test_rotation_about_z_kinetic_energy_is_the_inertia(robot, request):
    """Actuators at radius R, plates as discs (m r_p^2 / 2), connector and payload on the axis."""
    model = request.getfixturevalue(robot)
    lam = np.full(model.A, 0.95)
    inertia, q, v = _rigid(model, model.straight_state(lam)[:model.nq], lam,
                           omega=np.array([0.0, 0.0, 2.0]))
    cfg = model.cfg
    izz = 0.0
    for j, s in enumerate(cfg.segments):
        r_p = cfg.plate_radius_of(j)
        izz += s.n_actuators * cfg.rho0 * cfg.l0 * s.pitch_radius**2
        izz += (s.top_plate_mass + len(s.plate_fractions) * s.constraint_plate_mass) * r_p**2 / 2
    assert r_p == pytest.approx(0.020 + 0.0179 / 2)
    assert inertia.kinetic_energy(v, 0.1) == pytest.approx(0.5 * izz * 4.0, rel=1e-12)


@pytest.mark.parametrize("robot", ["one", "two"])
def test_mass_carries_the_static_gravity(robot, request):
    """``M_static(lam) g`` is the generalised gravity of eqs. (14)-(16): the same mass."""
    model = request.getfixturevalue(robot)
    lam = np.linspace(0.9, 1.2, model.A)
    inertia = Inertia(model)
    T = inertia.scale(lam)
    M = inertia.mass_matrix(0.03).toarray() * T[:, None] * T[None, :]
    G = np.zeros(model.nq)
    _, q, _ = _rigid(model, model.straight_state(lam)[:model.nq], lam)
    g = np.asarray(model.gravity)
    for dofs in [model.elem_dofs.reshape(-1, 4, 3)[:, [0, 2]].reshape(-1, 3),
                 model.plate_dofs[:, 0:3]]:
        G[dofs.ravel()] = np.tile(g, len(dofs))
    Q, _ = model.external_forces(lam, 1.0, 0.03)
    np.testing.assert_allclose(M @ G, Q, rtol=0, atol=1e-14)


def test_mass_is_symmetric_positive_on_the_tangent_space(two):
    fw = solve_forward(two, np.zeros(two.A))
    M = Inertia(two).mass_matrix().toarray()
    np.testing.assert_array_equal(M, M.T)
    nq = two.nq
    import scipy.linalg as sla
    Z = sla.null_space(fw.jacobian.toarray()[nq:, :nq])
    assert np.linalg.eigvalsh(Z.T @ M @ Z).min() > 0


@pytest.mark.parametrize("robot", ["one", "two"])
def test_damping_force_and_matrix_are_derivatives_of_the_dissipation(robot, request):
    model = request.getfixturevalue(robot)
    rng = np.random.default_rng(3)
    lam = rng.uniform(0.9, 1.15, model.A)
    x = model.straight_state(lam)
    x[:model.nq] += 2e-3 * rng.standard_normal(model.nq)
    inertia = Inertia(model, 0.005, 0.7)
    q = inertia.to_material(x[:model.nq], lam)
    v = rng.standard_normal(model.nq)
    f = inertia.damping_force(q, v, lam)
    h = 1e-3  # D is quadratic in the velocities: central differences are exact but for rounding
    diss = inertia.dissipation
    fd = np.array([(diss(q, v + h * e, lam) - diss(q, v - h * e, lam)) / (2 * h)
                   for e in np.eye(model.nq)])
    np.testing.assert_allclose(f, fd, rtol=1e-6, atol=1e-9 * np.abs(f).max())
    D = inertia.damping_matrix(q, lam)
    np.testing.assert_allclose(D @ v, f, rtol=1e-10, atol=1e-12 * np.abs(f).max())
    assert abs(D - D.T).max() < 1e-12 * abs(D).max()
    # a rigid motion dissipates nothing but the air damping's share
    _, q0, vr = _rigid(model, model.straight_state(lam)[:model.nq], lam,
                       omega=np.array([0.3, -0.4, 1.0]))
    kv_only = Inertia(model, 0.005, 0.0)
    assert abs(kv_only.dissipation(q0, vr, lam)) < 1e-12
    # the compiled right-hand side applies the same force
    s = inertia.scale(lam)
    par = model.element_parameters(lam)
    r = np.zeros(model.N)
    out = np.empty(model.N)
    M = inertia.mass_matrix_csr()
    acc = rng.standard_normal(model.nq)
    dynamic_rhs(q, v, acc, s, r, model.nq, M.indptr, M.indices, M.data,
                model.elem_dofs.astype(np.int64), model.elem_act.astype(np.int64), par["le"],
                par["kt"], par["kb"], model.kernel_args[2], model.kernel_args[3],
                model.kernel_args[4], inertia.damping_time, inertia.mass_damping, 2.0, out)
    np.testing.assert_allclose(-2.0 * out[:model.nq], M @ acc + f, rtol=1e-12,
                               atol=1e-12 * np.abs(f).max())


def test_bad_damping_named(one):
    with pytest.raises(ValueError, match="damping_time_s = -1.0 is not allowed"):
        Inertia(one, -1.0)
