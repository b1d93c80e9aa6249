"""core.inverse_warm: chord, refined and Newton steps give the same answers; held targets."""

import dataclasses

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, solve_inverse, warm_up
from bellow_ancf_ros.core.solve import _inverse_warm as warm


def _walk_targets(model, n, rng, step_pa=1.5e3):
    multi = model.cfg.n_segments > 1
    p = np.full(model.A, 30e3)
    out = []
    for _ in range(n):
        p = np.clip(p + rng.normal(0, step_pa, model.A), 5e3, 60e3)
        fw = solve_forward(model, p)
        out.append((fw.position, fw.z_axis if multi else None))
    return out


@pytest.mark.parametrize("name", ["one_segment", "two_segment"])
def test_answers_with_chord_steps_equal_newton_answers(name, monkeypatch):
    """Along a walk, the chord and refined steps give the answers of Newton's method alone."""
    model = RobotModel(load_robot(name))
    targets = _walk_targets(model, 12, np.random.default_rng(3))

    def walk():
        prev, out = None, []
        for pos, z in targets:
            prev = solve_inverse(model, pos, z, warm_start=prev)
            assert prev.success, prev.message
            out.append(prev)
        return out

    fast = walk()
    assert sum(r.forward.iterations for r in fast) > 0
    monkeypatch.setattr(warm, "MAX_CHORD", 0)  # no chord steps
    monkeypatch.setattr(warm, "REFINE_MAX", -1.0)  # no refinement: a factorisation per step
    newton = walk()
    for f, n in zip(fast, newton):
        assert np.linalg.norm(f.forward.position - n.forward.position) < 1e-9
        np.testing.assert_allclose(f.pressures_pa, n.pressures_pa, rtol=0, atol=1e-4)


def test_a_held_two_segment_target_is_accepted_without_a_factorisation(factorisations):
    model = RobotModel(load_robot("two_segment"))
    (pos, z), (pos2, z2) = _walk_targets(model, 2, np.random.default_rng(5))
    a = solve_inverse(model, pos, z)
    b = solve_inverse(model, pos2, z2, warm_start=a)
    assert b.success and b.forward._warm.exact
    factorisations.clear()
    held = solve_inverse(model, pos2, z2, warm_start=b)
    assert held.success and not factorisations  # the warm start's exact W proves the answer
    np.testing.assert_allclose(held.pressures_pa, b.pressures_pa, rtol=0, atol=1e-6)
    # a target that moves still gets its factorisation (the null-space condition is exact)
    moved = solve_inverse(model, pos2 + [2e-3, 0, 0], z2, warm_start=held)
    assert moved.success and len(factorisations) >= 1
    cold = solve_inverse(model, pos2 + [2e-3, 0, 0], z2)
    np.testing.assert_allclose(moved.pressures_pa, cold.pressures_pa, rtol=0, atol=1.0)


def test_second_order_predictor_starts_closer_along_a_steady_path():
    model = RobotModel(load_robot("two_segment"))
    centre = solve_forward(model, np.full(model.A, 30e3))
    phi = np.linspace(0, 0.3, 7)
    pos = centre.position + 0.02 * np.stack([np.cos(phi) - 1, np.sin(phi), 0 * phi], axis=1)
    first = []
    for use in (True, False):
        prev = solve_inverse(model, pos[0], centre.z_axis)
        for k in range(1, len(pos)):
            if not use:
                if prev.forward._warm is not None:
                    prev.forward._warm = dataclasses.replace(prev.forward._warm, path=None)
            prev = solve_inverse(model, pos[k], centre.z_axis, warm_start=prev)
            assert prev.success
        first.append(prev.forward.history[0])
    assert first[0] < 0.2 * first[1]  # the residual after the predictor


@pytest.mark.parametrize("shape, rank", [((6, 6), 5), ((5, 6), 5), ((3, 6), 3), ((6, 6), 6)])
def test_compiled_pseudo_inverse_and_projector_equal_numpy(shape, rank):
    """J_O pseudo-inverse (rcond cut) and null-space projector equal to what numpy makes."""
    rng = np.random.default_rng(rank + shape[0])
    u, _, vt = np.linalg.svd(rng.normal(size=(shape[0], shape[1])), full_matrices=False)
    s = np.logspace(0, -3, min(shape))
    s[rank:] = 1e-14  # round-off directions below the cut
    JO = (u * s) @ vt
    inv, proj = warm._pinv_projector(JO, warm.RCOND)
    ref = np.linalg.pinv(JO, rcond=warm.RCOND)
    np.testing.assert_allclose(inv, ref, rtol=0, atol=1e-10 * np.max(np.abs(ref)))
    np.testing.assert_allclose(proj, np.eye(shape[1]) - ref @ JO, rtol=0, atol=1e-12)
    assert np.linalg.matrix_rank(proj, tol=1e-8) == shape[1] - rank  # projects on the null space
    np.testing.assert_allclose(proj @ proj, proj, atol=1e-12)


def test_warm_up_compiles_the_fast_path_kernels(two):
    from bellow_ancf_ros.core.solve import _chord as chord

    assert warm_up(two)
    for kernel in (chord._chord_loop, chord.stretch_step, warm._pinv_projector):
        assert kernel.signatures  # compiled or loaded from the cache by the warm-up
