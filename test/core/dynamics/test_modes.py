"""Natural modes of equilibria (docs/dynamics.md): the independent table, pairs, damping."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.dynamics import ModalError, natural_modes, reduced_system

# An independent linearisation of the same model (shipped robot files, n = 6, plates as thin
# discs of radius R + D_a/2, Kelvin-Voigt retardation time 5 ms), vented: first lateral
# bending frequency [Hz] and damping ratio at 0, 50 and 100 g.
TABLE = {
    "one": [(0.0, 10.589, 0.172), (0.05, 6.159, 0.105), (0.1, 4.668, 0.084)],
    "two": [(0.0, 2.399, 0.050), (0.05, 1.454, 0.041), (0.1, 0.953, 0.041)],
}


@pytest.mark.parametrize("robot", ["one", "two"])
def test_first_frequencies_match_the_independent_table(robot, request):
    model = request.getfixturevalue(robot)
    for payload, f1, zeta in TABLE[robot]:
        ma = natural_modes(solve_forward(model, np.zeros(model.A), payload_kg=payload), 3)
        a, b = ma.modes[:2]
        assert round(a.frequency_hz, 3) == f1 and round(b.frequency_hz, 3) == f1
        assert round(a.damping_ratio, 3) == zeta
        # a lateral pair: the tip moves along base x, then y, with the same frequency
        np.testing.assert_allclose(a.direction, [1, 0, 0], atol=1e-6)
        np.testing.assert_allclose(b.direction, [0, 1, 0], atol=1e-6)
        assert a.damped_frequency_hz == pytest.approx(
            a.frequency_hz * np.sqrt(1 - a.damping_ratio**2), rel=0.02)
        assert ma.modes[2].frequency_hz > 1.5 * f1


def test_mass_proportional_damping_has_the_analytic_ratio(one):
    """Damping alpha M alone gives every mode zeta = alpha / (2 w) exactly."""
    fw = solve_forward(one, [100e3, -20e3, 0.0], payload_kg=0.02)
    ma = natural_modes(fw, 4, damping_time_s=0.0, mass_damping_per_s=3.0)
    for m in ma.modes:
        w = 2 * np.pi * m.frequency_hz
        assert m.damping_ratio == pytest.approx(3.0 / (2 * w), rel=1e-8)
        assert m.damped_frequency_hz == pytest.approx(
            m.frequency_hz * np.sqrt(1 - m.damping_ratio**2), rel=1e-8)
    undamped = natural_modes(fw, 2, damping_time_s=0.0, mass_damping_per_s=0.0)
    assert undamped.first.damping_ratio == pytest.approx(0.0, abs=1e-9)
    assert undamped.first.frequency_hz == pytest.approx(ma.first.frequency_hz, rel=1e-12)


def test_light_damping_ratio_is_the_modal_projection(one):
    """For light damping zeta = phi^T D phi / (2 w) (unit modal mass): first-order perturbation.

    With mostly bending energy this is about beta w / 2 (docs/dynamics.md).
    """
    fw = solve_forward(one, np.zeros(3))
    red = reduced_system(fw)
    phi = red.V[:, 0]
    w = np.sqrt(red.w2[0])
    beta = 2e-4
    zeta = natural_modes(fw, 1, damping_time_s=beta, mass_damping_per_s=0.0).first.damping_ratio
    assert zeta == pytest.approx(beta * phi @ red.D_kv @ phi / (2 * w), rel=0.01)
    assert zeta == pytest.approx(beta * w / 2, rel=0.1)


def test_rayleigh_quotient_and_orthogonality(two):
    fw = solve_forward(two, np.zeros(two.A), payload_kg=0.05)
    red = reduced_system(fw)
    V = red.V[:, :6]
    np.testing.assert_allclose(V.T @ red.M @ V, np.eye(6), atol=1e-9)
    np.testing.assert_allclose(np.diag(V.T @ red.K @ V), red.w2[:6], rtol=1e-9)


def test_three_segments_tip_force_and_loaded_pressures(three):
    """Any segment count; a compressive tip force softens the lateral mode, tension stiffens it."""
    p = np.zeros(three.A)
    base = natural_modes(solve_forward(three, p), 2).first.frequency_hz
    down = natural_modes(solve_forward(three, p, tip_force_n=[0, 0, -0.03]), 2).first.frequency_hz
    up = natural_modes(solve_forward(three, p, tip_force_n=[0, 0, 0.03]), 2).first.frequency_hz
    assert down < base < up
    bent = solve_forward(three, np.array([60e3, 0, 0] * 3))
    ma = natural_modes(bent, 4)
    assert all(np.isfinite(m.frequency_hz) and m.frequency_hz > 0 for m in ma.modes)
    assert np.all(np.diff([m.frequency_hz for m in ma.modes]) >= -1e-9)
    d = ma.to_dict()
    assert set(d["modes"][0]) == {"frequency_hz", "damped_frequency_hz", "damping_ratio",
                                  "direction"}
    shape = ma.backbones(0, 0.01)
    assert shape.shape == (three.A, 20, 3)


def test_unconverged_equilibrium_refused(one):
    fw = solve_forward(one, np.zeros(3), max_iter=1, iteration_budget=1)
    if fw.converged:  # pragma: no cover - the cold solve needs more than one iteration
        pytest.skip("converged in one iteration")
    with pytest.raises(ModalError, match="did not converge"):
        natural_modes(fw)


@pytest.mark.parametrize('name, payload', [('one_segment', 0.0), ('two_segment', 0.05)])
def test_newton_damped_modes_equal_the_pencils(name, payload):
    """A few modes: Newton on the quadratic eigenproblem; many: the dense pencil. Same answer."""
    from bellow_ancf_ros.core.dynamics import _modes
    model = RobotModel(load_robot(name))
    fw = solve_forward(model, np.zeros(model.A), payload_kg=payload)
    few, many = natural_modes(fw, _modes._NEWTON_MODES).modes, natural_modes(fw, 6).modes
    for a, b in zip(few, many):
        assert a.damping_ratio == pytest.approx(b.damping_ratio, rel=1e-9)
        assert a.damped_frequency_hz == pytest.approx(b.damped_frequency_hz, rel=1e-9)


def test_the_docs_show_the_table():
    """docs/dynamics.md's table of first modes is this test's (the values it checks)."""
    import pathlib
    import re
    doc = (pathlib.Path(__file__).parents[3] / 'docs' / 'dynamics.md').read_text()
    rows = {'one': '| one segment |', 'two': '| two segments |'}
    for robot, start in rows.items():
        line = next(ln for ln in doc.splitlines() if ln.startswith(start) and 'Hz' in ln)
        cells = [re.findall(r'\d+\.\d+', c) for c in line.strip('|').split('|')[1:]]
        assert cells == [[f'{f:.3f}', f'{z:.3f}'] for _, f, z in TABLE[robot]], (robot, line)


def test_an_svd_that_does_not_converge_falls_back_and_a_bad_jacobian_is_a_modal_error(
        monkeypatch):
    """The SVD of LAPACK's gesdd did not converge once in the family's loops: gesvd instead."""
    import scipy.linalg as sla
    from bellow_ancf_ros.core.dynamics import _modes
    model = RobotModel(load_robot('one_segment'))
    fw = solve_forward(model, np.array([20e3, 0.0, 5e3]))
    want = natural_modes(fw, 1).first.frequency_hz
    real_null = sla.null_space
    drivers = []

    def flaky_svd(a, *args, **kwargs):   # numpy's gesdd (it releases the interpreter)
        drivers.append('gesdd')
        raise np.linalg.LinAlgError('SVD did not converge')

    def null_space(a, *args, lapack_driver='gesdd', **kwargs):
        drivers.append(lapack_driver)
        return real_null(a, *args, lapack_driver=lapack_driver, **kwargs)

    monkeypatch.setattr(_modes.np.linalg, 'svd', flaky_svd)
    monkeypatch.setattr(_modes.sla, 'null_space', null_space)
    assert natural_modes(fw, 1).first.frequency_hz == pytest.approx(want, rel=1e-9)
    assert drivers == ['gesdd', 'gesvd']
    monkeypatch.setattr(_modes.sla, 'null_space', lambda *a, **k: (_ for _ in ()).throw(
        np.linalg.LinAlgError('SVD did not converge')))
    with pytest.raises(ModalError, match='null space'):
        natural_modes(fw, 1)
    with pytest.raises(ModalError, match='not finite'):
        _modes._null_space(np.array([[np.nan, 1.0]]))


def test_a_modal_analysis_lets_other_threads_run():
    """A node computes modes in a thread beside its control thread: the interpreter is released.

    scipy.linalg's ``eig`` of the pencil held it for its whole call (0.18 s of
    a 0.23 s analysis of two segments): the inverse node's commands waited.
    Now a thread that sleeps 1 ms at a time wakes all through the analysis.
    """
    import threading
    import time
    model = RobotModel(load_robot('two_segment'))
    fw = solve_forward(model, np.zeros(model.A))
    natural_modes(fw, 6)
    stop, woke = threading.Event(), []

    def probe():
        while not stop.is_set():
            time.sleep(0.001)
            woke.append(time.perf_counter())
    thread = threading.Thread(target=probe)
    thread.start()
    time.sleep(0.01)
    t0 = time.perf_counter()
    for _ in range(3):
        natural_modes(fw, 6)
    t1 = time.perf_counter()
    stop.set()
    thread.join()
    during = np.array([t0] + [t for t in woke if t0 <= t <= t1] + [t1])
    assert np.max(np.diff(during)) < 0.25 * (t1 - t0) / 3, (np.max(np.diff(during)), t1 - t0)
