"""Old versus new: today's solver reproduces the recorded results of the pre-rewrite code.

``test/data/solver_baseline.npz`` was written by ``test/data/make_solver_baseline.py``
from the code before the real-time rewrite (compiled kernels, banded stability
test).  Positions must agree to 1e-9 m; the residual, the KKT Jacobian (eq. 27)
and dR/dlam (eq. 30) to round-off.
"""

import os
import sys

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_forward, solve_inverse

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "data"))
import make_solver_baseline as mb  # noqa: E402

BASE = np.load(os.path.join(os.path.dirname(__file__), "data", "solver_baseline.npz"))
POS_TOL = 1e-9  # m


@pytest.mark.parametrize("k", range(len(mb.EVAL_CASES)))
def test_evaluation_equals_recorded(k):
    model = mb.model_for(*mb.EVAL_CASES[k])
    x, lam = mb.eval_state(model, 100 + k)
    ev = model.evaluate(x, lam, 0.8, 0.07, jacobian=True, lam_derivative=True)
    for key, new in (
        ("residual", ev.residual),
        ("jacobian", ev.jacobian.toarray()),
        ("dres_dlam", ev.dres_dlam),
    ):
        old = BASE[f"eval{k}_{key}"]
        np.testing.assert_allclose(new, old, rtol=0, atol=1e-11 * np.abs(old).max(), err_msg=key)


@pytest.mark.parametrize("k", range(len(mb.FORWARD_CASES)))
@pytest.mark.parametrize("mode", ["cold", "warm"])
def test_forward_fuzz_equals_recorded(k, mode):
    name, n, count = mb.FORWARD_CASES[k]
    model = mb.model_for(name, n)
    p, m = BASE[f"fwd{k}_pressures"], BASE[f"fwd{k}_payload"]
    key = f"fwd{k}_{mode}"
    prev = None
    for i in range(count):
        fw = solve_forward(model, p[i], m[i], warm_start=prev if mode == "warm" else None)
        if mode == "warm" and fw.converged:
            prev = fw
        assert fw.converged == BASE[key + "_converged"][i]
        assert fw.stable == BASE[key + "_stable"][i]
        np.testing.assert_allclose(fw.position, BASE[key + "_position"][i], rtol=0, atol=POS_TOL)
        np.testing.assert_allclose(fw.rotation, BASE[key + "_rotation"][i], rtol=0, atol=1e-8)
        plates = np.array([pp[2] for pp in fw.plate_poses()])
        np.testing.assert_allclose(plates, BASE[key + "_plates"][i], rtol=0, atol=POS_TOL)
        assert fw.min_eigenvalue == pytest.approx(BASE[key + "_min_eig"][i], rel=1e-6)


@pytest.mark.parametrize("k", range(len(mb.INVERSE_CASES)))
def test_inverse_fuzz_equals_recorded(k):
    name, n, count = mb.INVERSE_CASES[k]
    model = mb.model_for(name, n)
    multi = model.cfg.n_segments > 1
    z = BASE[f"inv{k}_z"]
    prev = None
    for i, target in enumerate(BASE[f"inv{k}_targets"]):
        prev = solve_inverse(model, target, z[i] if multi else None, warm_start=prev)
        assert prev.status == BASE[f"inv{k}_status"][i]
        np.testing.assert_allclose(
            prev.forward.position, BASE[f"inv{k}_position"][i], rtol=0, atol=POS_TOL
        )
        # pressures: the same answer up to the solver tolerance (1e-8 of the robot length)
        np.testing.assert_allclose(
            prev.pressures_pa, BASE[f"inv{k}_pressures"][i], rtol=0, atol=1e-2
        )


def test_unstable_fuzz_equals_recorded():
    model = mb.model_for("two_segment", 6)
    for i, m in enumerate(mb.UNSTABLE_PAYLOADS):
        fw = solve_forward(model, np.zeros(model.A), m)
        assert fw.stable == BASE["unstable_stable"][i]
        np.testing.assert_allclose(fw.position, BASE["unstable_position"][i], rtol=0, atol=POS_TOL)
        assert fw.min_eigenvalue == pytest.approx(BASE["unstable_min_eig"][i], rel=1e-6)
