"""Record the solver's results on a seeded fuzz set into ``solver_baseline.npz``.

Run once from the code *before* the real-time rewrite (issue 11, commit 1f2d442):
``python test/data/make_solver_baseline.py``.  ``test/test_solver_baseline.py``
compares today's code with these numbers (old versus new, 1e-9 m).

Recorded: residual, KKT Jacobian (dense) and dR/dlam at perturbed states;
cold and warm-started forward solves at random pressures and payloads
(end-effector pose, plate positions, stability); warm-started inverse solves
along short random paths (pressures, predicted position, status).
"""

from __future__ import annotations

import os

import numpy as np

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, solve_inverse
from bellow_ancf_ros.core import limit_blas_threads

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "solver_baseline.npz")

# (robot, elements per actuator, tool length)
EVAL_CASES = [("one_segment", 6, 0.0), ("one_segment", 4, 0.0), ("two_segment", 4, 0.02)]
FORWARD_CASES = [("one_segment", 6, 10), ("one_segment", 4, 4), ("two_segment", 6, 6)]
UNSTABLE_PAYLOADS = (0.15, 0.25, 0.4)
INVERSE_CASES = [("one_segment", 6, 8), ("two_segment", 6, 5)]


def model_for(name, n, tool=0.0):
    """Robot model of the fuzz set."""
    cfg = load_robot(name)
    if tool:
        cfg = cfg.replace(tool_length=tool)
    return RobotModel(cfg, n)


def eval_state(model, seed):
    """Perturbed state with non-zero multipliers (they exercise the constraint Hessian).

    Also the states of test_assembly's and test_linsolve's Jacobian and solve checks.
    """
    rng = np.random.default_rng(seed)
    lam = rng.uniform(model.stage1.lam_min, model.stage1.lam_max, model.A)
    x = model.straight_state(lam)
    x[: model.nq] += 1e-3 * rng.standard_normal(model.nq)
    x[model.nq:] = rng.standard_normal(model.nc)
    return x, lam


def fuzz_pressures(model, seed, count):
    """Random pressures inside the limits and payloads in [0, 0.1] kg."""
    rng = np.random.default_rng(seed)
    cfg = model.cfg
    p = rng.uniform(cfg.p_min, cfg.p_max, (count, model.A))
    m = rng.uniform(0.0, 0.1, count)
    return p, m


def inverse_path(model, seed, count):
    """Targets: forward poses of a random pressure walk (steps of about 1 mm)."""
    rng = np.random.default_rng(seed)
    cfg = model.cfg
    p = np.full(model.A, 0.3 * cfg.p_max)
    fw = solve_forward(model, p)
    pos, z = [], []
    for _ in range(count):
        p = np.clip(p + rng.normal(0.0, 4e3, model.A), cfg.p_min, cfg.p_max)
        fw = solve_forward(model, p, warm_start=fw)
        pos.append(fw.position)
        z.append(fw.z_axis)
    return np.array(pos), np.array(z)


def main():
    """Write the fixture."""
    limit_blas_threads()
    out = {}
    for k, (name, n, tool) in enumerate(EVAL_CASES):
        model = model_for(name, n, tool)
        x, lam = eval_state(model, 100 + k)
        ev = model.evaluate(x, lam, 0.8, 0.07, jacobian=True, lam_derivative=True)
        out[f"eval{k}_residual"] = ev.residual
        out[f"eval{k}_jacobian"] = ev.jacobian.toarray()
        out[f"eval{k}_dres_dlam"] = ev.dres_dlam
    for k, (name, n, count) in enumerate(FORWARD_CASES):
        model = model_for(name, n)
        p, m = fuzz_pressures(model, 200 + k, count)
        for mode in ("cold", "warm"):
            pos, rot, plates, stable, conv, mineig = [], [], [], [], [], []
            prev = None
            for i in range(count):
                fw = solve_forward(model, p[i], m[i], warm_start=prev if mode == "warm" else None)
                if mode == "warm" and fw.converged:
                    prev = fw
                pos.append(fw.position)
                rot.append(fw.rotation)
                plates.append(np.array([pp[2] for pp in fw.plate_poses()]))
                stable.append(bool(fw.stable))
                conv.append(bool(fw.converged))
                mineig.append(fw.min_eigenvalue if fw.converged else np.nan)
            key = f"fwd{k}_{mode}"
            out[key + "_position"] = np.array(pos)
            out[key + "_rotation"] = np.array(rot)
            out[key + "_plates"] = np.array(plates)
            out[key + "_stable"] = np.array(stable)
            out[key + "_converged"] = np.array(conv)
            out[key + "_min_eig"] = np.array(mineig)
        out[f"fwd{k}_pressures"] = p
        out[f"fwd{k}_payload"] = m
    for k, (name, n, count) in enumerate(INVERSE_CASES):
        model = model_for(name, n)
        pos, z = inverse_path(model, 300 + k, count)
        multi = model.cfg.n_segments > 1
        prev = None
        pres, fpos, status = [], [], []
        for i in range(count):
            prev = solve_inverse(model, pos[i], z[i] if multi else None, warm_start=prev)
            pres.append(prev.pressures_pa)
            fpos.append(prev.forward.position)
            status.append(prev.status)
        key = f"inv{k}"
        out[key + "_targets"] = pos
        out[key + "_z"] = z
        out[key + "_pressures"] = np.array(pres)
        out[key + "_position"] = np.array(fpos)
        out[key + "_status"] = np.array(status)
    # beyond the buckling payload of the straight two-segment robot: unstable answers
    model = model_for("two_segment", 6)
    unstable = [solve_forward(model, np.zeros(model.A), m) for m in UNSTABLE_PAYLOADS]
    out["unstable_stable"] = np.array([bool(fw.stable) for fw in unstable])
    out["unstable_min_eig"] = np.array([fw.min_eigenvalue for fw in unstable])
    out["unstable_position"] = np.array([fw.position for fw in unstable])
    np.savez_compressed(OUT, **out)
    print(f"wrote {OUT} ({len(out)} arrays)")


if __name__ == "__main__":
    main()
