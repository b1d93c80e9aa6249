"""Model studies: element convergence, workspace, PCC comparison, offline tracking.

numpy/scipy only (no ROS, no plotting: the CLI in ``bellow_ancf_ros.cli.studies``
and ``bellow_ancf_ros.cli.track`` draws).  Every study takes an optional
``progress(done, total, text)`` callback for long runs.

* :func:`convergence_study` (paper V.D, Fig. 4(d)): end-effector error of
  ``n = 1..12`` elements per actuator against a converged reference
  (``n = 48``) at extreme actuations, and the solve time.  The
  recommendation is the smallest element count whose error is below a
  threshold (default 0.01 mm) *and* that puts a node on every plate
  (``s_k * n`` integer for every plate fraction ``s_k``): a plate inside an
  element makes the cubic element follow a curvature jump it cannot
  represent (docs/model.md section 6), so such counts converge erratically.
* :func:`workspace_study` (paper VI.B): the paper's actuation schemes swept
  from ``p_min`` to ``p_max`` with warm-started forward solves, per payload.
  One segment: 18 schemes (each actuator swept with the other two at every
  combination of ``p_min``/``p_max``: 12; each pair swept with the third at
  ``p_min`` or ``p_max``: 6).  Two segments: the paper's four schemes
  (``s11+s21``, ``s11+s22``, ``s11+s21+s22``, ``s11+s22+s23`` swept, the others
  at 0 kPa).
* :func:`compare_pcc`: the same sweeps (plus a pure elongation sweep) with
  the ANCF model and the PCC model (:mod:`.pcc`), per payload.
* :func:`tracking_study` (paper VI.C): inverse along a trajectory of
  :mod:`.trajectories`, warm-started point to point; the errors are those of
  a forward solve at the returned pressures (the model's prediction of where
  the feedforward sends the tip).
* :func:`stiffness_study` (the paper's claim that the model predicts the
  "vertical stiffness with different actuation pressures"): the tip's
  vertical stiffness at equal pressures from ``p_min`` to ``p_max``, per
  payload; :func:`stiffness_along_trajectory`: the tip stiffness at the
  feedforward answers along a trajectory (both from
  :func:`~bellow_ancf_ros.core.solve.tip_compliance`, exact at each equilibrium).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..geometry import angle_between
from ..model import ConfigError, PccModel, RobotConfig, RobotModel
from ..solve import solve_forward, solve_inverse, tip_compliance
from . import trajectories

__all__ = [
    'nodes_on_plates', 'extreme_actuations', 'ConvergenceRow', 'ConvergenceResult',
    'convergence_study', 'Scheme', 'workspace_schemes', 'elongation_scheme', 'sweep_scheme',
    'workspace_study', 'compare_pcc', 'TrackResult', 'tracking_study', 'stiffness_study',
    'stiffness_along_trajectory',
]

Progress = Callable[[int, int, str], None]


def _noop(done, total, text):  # pragma: no cover - trivial
    pass


# ============================================================ convergence
def nodes_on_plates(cfg: RobotConfig, n: int, tol: float = 1e-9) -> bool:
    """True when ``n`` elements put a node on every plate of every segment."""
    for seg in cfg.segments:
        for s in seg.plate_fractions:
            if abs(s * n - round(s * n)) > tol:
                return False
    return True


def extreme_actuations(cfg: RobotConfig) -> dict[str, np.ndarray]:
    """Extreme actuations of the convergence study [Pa], by name.

    ``paper``: actuator 1 at ``p_max``, the others at 0 (paper V.D);
    ``a1_max_rest_min``: actuator 1 at ``p_max``, all others at ``p_min``;
    ``a1a2_max_rest_min``: actuators 1 and 2 at ``p_max``, the others at
    ``p_min``; for two or more segments also ``first_of_each_max_rest_min``.
    """
    A = cfg.n_actuators_total
    hi, lo = cfg.p_max, cfg.p_min
    out = {
        'paper': np.r_[hi, np.zeros(A - 1)],
        'a1_max_rest_min': np.r_[hi, np.full(A - 1, lo)],
        'a1a2_max_rest_min': np.r_[hi, hi, np.full(A - 2, lo)],
    }
    if cfg.n_segments >= 2:
        p = np.full(A, lo)
        for sl in cfg.actuator_slices:
            p[sl.start] = hi
        out['first_of_each_max_rest_min'] = p
    return out


@dataclass
class ConvergenceRow:
    n: int
    nodes_on_plates: bool
    error_m: float | None          # max over the actuations (None: a solve failed)
    errors_m: dict                 # per actuation
    time_s: float                  # median solve time per forward solve
    converged: bool
    refused: str = ''              # why the count cannot carry the plates (RobotModel refuses it)


@dataclass
class ConvergenceResult:
    config_name: str
    reference_n: int
    threshold_m: float
    payload_kg: float
    actuations_pa: dict
    reference_positions_m: dict
    reference_time_s: float
    rows: list
    recommended: int | None
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {
            'config': self.config_name,
            'reference_n': self.reference_n,
            'threshold_m': self.threshold_m,
            'payload_kg': self.payload_kg,
            'actuations_pa': {k: v.tolist() for k, v in self.actuations_pa.items()},
            'reference_positions_m': {k: v.tolist()
                                      for k, v in self.reference_positions_m.items()},
            'reference_time_s': self.reference_time_s,
            'rows': [dict(n=r.n, nodes_on_plates=r.nodes_on_plates, error_m=r.error_m,
                          errors_m=r.errors_m, time_s=r.time_s, converged=r.converged,
                          refused=r.refused)
                     for r in self.rows],
            'recommended_n': self.recommended,
            'reason': self.reason,
        }


def _timed_forward(model, p, payload, repeats):
    times, fw = [], None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fw = solve_forward(model, p, payload)
        times.append(time.perf_counter() - t0)
    return fw, times


def convergence_study(cfg: RobotConfig, counts: Sequence[int] = tuple(range(1, 13)),
                      reference_n: int = 48, threshold_m: float = 1e-5, payload_kg: float = 0.0,
                      actuations: dict | None = None, repeats: int = 3,
                      progress: Progress | None = None) -> ConvergenceResult:
    """Tip error of each element count against the ``reference_n`` solution (paper Fig. 4(d)).

    For each count the error is the largest end-effector position error over
    the ``actuations`` (default :func:`extreme_actuations`); the time is the
    median of ``repeats`` cold forward solves per actuation.  A count whose
    solve fails gets ``error_m = None``; so does a count that cannot carry
    the plates (``n = 1, 2`` with plates at 1/3 and 2/3), with the reason in
    ``refused``.
    """
    progress = progress or _noop
    counts = sorted({int(n) for n in counts})
    if not counts or counts[0] < 1:
        raise ValueError('element counts must be >= 1')
    if reference_n < 1:
        raise ValueError('the reference element count must be >= 1')
    acts = extreme_actuations(cfg) if actuations is None else dict(actuations)
    total = len(counts) + 1
    progress(0, total, f'reference n = {reference_n}')
    ref_model = RobotModel(cfg, reference_n)
    ref_pos, ref_times = {}, []
    for key, p in acts.items():
        fw, times = _timed_forward(ref_model, p, payload_kg, 1)
        if not fw.converged:
            raise RuntimeError(f'the reference solve (n = {reference_n}, {key}) did not '
                               f'converge: {fw.message}')
        ref_pos[key] = fw.position.copy()
        ref_times += times
    rows = []
    for i, n in enumerate(counts, start=1):
        progress(i, total, f'n = {n}')
        try:
            model = RobotModel(cfg, n)
        except ConfigError as exc:  # cannot carry the plates: no answer, not a wrong one
            rows.append(ConvergenceRow(n, nodes_on_plates(cfg, n), None, {k: None for k in acts},
                                       float('nan'), False, exc.issues[0][1]))
            continue
        errs, times, ok = {}, [], True
        for key, p in acts.items():
            fw, t = _timed_forward(model, p, payload_kg, repeats)
            times += t
            if fw.converged:
                errs[key] = float(np.linalg.norm(fw.position - ref_pos[key]))
            else:
                errs[key] = None
                ok = False
        err = max(errs.values()) if ok else None
        rows.append(ConvergenceRow(n, nodes_on_plates(cfg, n), err, errs,
                                   float(np.median(times)), ok))
    progress(total, total, 'done')
    rec, reason = None, ''
    for r in rows:
        if r.error_m is not None and r.error_m <= threshold_m and r.nodes_on_plates:
            rec = r.n
            reason = (f'smallest element count with an error below {threshold_m * 1e3:g} mm '
                      f'({r.error_m * 1e3:.2g} mm) and a node on every plate')
            break
    if rec is None:
        below = [r for r in rows if r.error_m is not None and r.error_m <= threshold_m]
        if below:
            rec = below[0].n
            reason = (f'no tested count puts nodes on every plate with an error below '
                      f'{threshold_m * 1e3:g} mm; smallest count below the threshold')
        else:
            reason = f'no tested count reaches an error below {threshold_m * 1e3:g} mm'
    return ConvergenceResult(cfg.name, int(reference_n), float(threshold_m), float(payload_kg),
                             acts, ref_pos, float(np.median(ref_times)), rows, rec, reason)


# ============================================================== workspace
@dataclass
class Scheme:
    """An actuation scheme.

    The ``swept`` actuators go ``p_min -> p_max`` together, the others stay fixed.
    """

    name: str
    swept: tuple
    fixed: dict  # actuator index -> pressure [Pa]

    def pressures(self, cfg: RobotConfig, n_points: int) -> np.ndarray:
        A = cfg.n_actuators_total
        ramp = np.linspace(cfg.p_min, cfg.p_max, n_points)
        P = np.zeros((n_points, A))
        for i, v in self.fixed.items():
            P[:, i] = v
        for i in self.swept:
            P[:, i] = ramp
        return P


def _act_label(cfg: RobotConfig, i: int) -> str:
    for j, sl in enumerate(cfg.actuator_slices):
        if sl.start <= i < sl.stop:
            return f's{j + 1}{i - sl.start + 1}' if cfg.n_segments > 1 else f'a{i + 1}'
    raise IndexError(i)  # pragma: no cover


def workspace_schemes(cfg: RobotConfig) -> list[Scheme]:
    """The paper's workspace schemes (section VI.B) for ``cfg``.

    One segment: 18 schemes for three actuators (in general: every actuator
    swept with the others at every min/max combination, then every pair
    swept with the others at every combination).  Two segments: the paper's
    four schemes (actuator 1 of segment 1 with actuators 1; 2; 1 and 2; 2 and
    3 of segment 2) with the other actuators at 0 kPa.  Three or more: the
    same four, each pattern of segment 2 repeated in every later segment
    (so that every segment moves).
    """
    A = cfg.n_actuators_total
    lo, hi = cfg.p_min, cfg.p_max
    tag = {lo: 'min', hi: 'max'}
    out = []
    if cfg.n_segments == 1:
        for k in (1, 2):
            for swept in itertools.combinations(range(A), k):
                rest = [i for i in range(A) if i not in swept]
                for combo in itertools.product((lo, hi), repeat=len(rest)):
                    fixed = dict(zip(rest, combo))
                    name = '+'.join(_act_label(cfg, i) for i in swept) + ' swept; ' + ', '.join(
                        f'{_act_label(cfg, i)}={tag[v]}' for i, v in fixed.items())
                    out.append(Scheme(name, swept, fixed))
        return out
    a = cfg.actuator_slices[0].start
    later = [sl.start for sl in cfg.actuator_slices[1:]]
    patterns = [(0,), (1,), (0, 1), (1, 2)]
    groups = [(a,) + tuple(b + j for b in later for j in pat) for pat in patterns]
    for swept in groups:
        fixed = {i: 0.0 for i in range(A) if i not in swept}
        name = '+'.join(_act_label(cfg, i) for i in swept) + ' swept; others 0 kPa'
        out.append(Scheme(name, tuple(swept), fixed))
    return out


def elongation_scheme(cfg: RobotConfig) -> Scheme:
    """All actuators swept together: pure elongation/contraction."""
    return Scheme('all swept (elongation)', tuple(range(cfg.n_actuators_total)), {})


def sweep_scheme(model: RobotModel, scheme: Scheme, n_points: int, payload_kg: float = 0.0):
    """Forward solves along a scheme, warm-started: list of ForwardResult (``n_points``)."""
    out, prev = [], None
    for p in scheme.pressures(model.cfg, n_points):
        fw = solve_forward(model, p, payload_kg, warm_start=prev)
        if not fw.converged:  # retry cold: a failed warm continuation should not end the sweep
            fw = solve_forward(model, p, payload_kg)
        out.append(fw)
        prev = fw if fw.converged else prev
    return out


def workspace_study(cfg: RobotConfig, payloads_kg: Sequence[float] = (0.0, 0.05, 0.1),
                    n_points: int = 21, n_elements: int | None = None,
                    schemes: Sequence[Scheme] | None = None,
                    progress: Progress | None = None) -> dict[str, Any]:
    """Workspace boundary curves (paper VI.B) for each payload.

    Returns ``{'config', 'payloads_kg', 'schemes': [names], 'rows': [...]}``;
    a row per solve: ``payload_kg, scheme (index), scheme_name, step,
    pressures_pa, position_m, z_axis, converged, stable``.
    """
    progress = progress or _noop
    if n_points < 2:
        raise ValueError('a sweep needs at least 2 points')
    model = RobotModel(cfg, n_elements)
    schemes = list(workspace_schemes(cfg) if schemes is None else schemes)
    rows = []
    total = len(payloads_kg) * len(schemes)
    done = 0
    for m in payloads_kg:
        for k, sc in enumerate(schemes):
            progress(done, total, f'payload {m:g} kg, scheme {k + 1}/{len(schemes)}: {sc.name}')
            for step, fw in enumerate(sweep_scheme(model, sc, n_points, m)):
                rows.append(dict(payload_kg=float(m), scheme=k, scheme_name=sc.name, step=step,
                                 pressures_pa=fw.pressures_pa.copy(),
                                 position_m=fw.position.copy(), z_axis=fw.z_axis.copy(),
                                 converged=bool(fw.converged), stable=fw.stable))
            done += 1
    progress(total, total, 'done')
    return dict(config=cfg.name, payloads_kg=[float(m) for m in payloads_kg],
                schemes=[s.name for s in schemes], n_points=int(n_points), n_elements=model.n,
                rows=rows)


# ============================================================ PCC vs ANCF
def compare_pcc(cfg: RobotConfig, payloads_kg: Sequence[float] = (0.0, 0.05, 0.1),
                n_points: int = 11, n_elements: int | None = None, gravity: bool = True,
                schemes: Sequence[Scheme] | None = None,
                progress: Progress | None = None) -> dict[str, Any]:
    """End-effector positions of the ANCF and PCC models along the same actuations.

    The actuations: a pure elongation sweep (category ``elongation``) and the
    workspace schemes (category ``bending``).  ``gravity=False`` switches the
    ANCF model's gravity off (the PCC model has none).  Returns the rows
    (``payload_kg, category, scheme_name, step, pressures_pa, ancf_m, pcc_m,
    diff_m, angle_rad, converged``) and a summary per payload and category
    (``points``, ``usable``: converged and stable ones, over which ``rms_m,
    max_m, mean_dz_m`` with ``dz = z_ancf - z_pcc`` and ``max_angle_rad``
    between the z-axes are taken; None when no point is usable).
    """
    progress = progress or _noop
    cfg_a = cfg if gravity else cfg.replace(gravity=(0.0, 0.0, 0.0))
    model = RobotModel(cfg_a, n_elements)
    pcc = PccModel(cfg)
    items = [('elongation', elongation_scheme(cfg))]
    items += [('bending', s) for s in (workspace_schemes(cfg) if schemes is None else schemes)]
    rows = []
    total = len(payloads_kg) * len(items)
    done = 0
    for m in payloads_kg:
        for cat, sc in items:
            progress(done, total, f'payload {m:g} kg: {sc.name}')
            for step, fw in enumerate(sweep_scheme(model, sc, n_points, m)):
                pc = pcc.forward(fw.pressures_pa)
                ok = fw.success
                d = fw.position - pc.position if ok else np.full(3, np.nan)
                ang = angle_between(fw.z_axis, pc.z_axis) if ok else float('nan')
                rows.append(dict(payload_kg=float(m), category=cat, scheme_name=sc.name, step=step,
                                 pressures_pa=fw.pressures_pa.copy(), ancf_m=fw.position.copy(),
                                 pcc_m=pc.position.copy(), diff_m=float(np.linalg.norm(d)),
                                 dz_m=float(d[2]), angle_rad=ang, converged=ok))
            done += 1
    progress(total, total, 'done')
    summary = []
    for m in payloads_kg:
        for cat in ('elongation', 'bending'):
            mine = [r for r in rows if r['payload_kg'] == float(m) and r['category'] == cat]
            sel = [r for r in mine if r['converged']]
            row = dict(payload_kg=float(m), category=cat, points=len(mine), usable=len(sel),
                       rms_m=None, max_m=None, mean_dz_m=None, max_angle_rad=None)
            if sel:  # no usable equilibrium (the robot buckles under the payload): no figures
                d = np.array([r['diff_m'] for r in sel])
                row.update(rms_m=float(np.sqrt(np.mean(d ** 2))), max_m=float(np.max(d)),
                           mean_dz_m=float(np.mean([r['dz_m'] for r in sel])),
                           max_angle_rad=float(np.max([r['angle_rad'] for r in sel])))
            summary.append(row)
    return dict(config=cfg.name, gravity=bool(gravity),
                payloads_kg=[float(m) for m in payloads_kg], n_points=int(n_points),
                n_elements=model.n, rows=rows, summary=summary)


# =============================================================== tracking
@dataclass
class TrackResult:
    """Offline feedforward tracking along a trajectory (SI units)."""

    config_name: str
    trajectory: str
    payload_kg: float
    times_s: np.ndarray
    targets_m: np.ndarray
    target_z_axes: np.ndarray | None
    pressures_pa: np.ndarray
    predicted_m: np.ndarray
    predicted_z_axes: np.ndarray
    position_errors_m: np.ndarray
    angle_errors_rad: np.ndarray | None
    reachable: np.ndarray
    success: np.ndarray
    solve_times_s: np.ndarray
    params: dict = field(default_factory=dict)
    controller: str = 'ancf'

    def stats(self) -> dict[str, Any]:
        pe = self.position_errors_m
        fin = np.isfinite(pe)
        out = {
            'points': int(pe.size),
            'position_rms_m': float(np.sqrt(np.mean(pe[fin] ** 2))) if fin.any() else None,
            'position_max_m': float(np.max(pe[fin])) if fin.any() else None,
            'reachable_fraction': float(np.mean(self.reachable)),
            'success_fraction': float(np.mean(self.success)),
            'solve_time_median_s': float(np.median(self.solve_times_s)),
            'solve_time_p99_s': float(np.percentile(self.solve_times_s, 99)),
            'solve_time_max_s': float(np.max(self.solve_times_s)),
            'angle_rms_rad': None,
            'angle_max_rad': None,
        }
        if self.angle_errors_rad is not None:
            ae = self.angle_errors_rad[np.isfinite(self.angle_errors_rad)]
            if ae.size:
                out['angle_rms_rad'] = float(np.sqrt(np.mean(ae ** 2)))
                out['angle_max_rad'] = float(np.max(ae))
        return out

    def to_dict(self) -> dict[str, Any]:
        d = {'config': self.config_name, 'trajectory': self.trajectory,
             'payload_kg': self.payload_kg, 'controller': self.controller, 'params': self.params}
        d.update(self.stats())
        return d


def tracking_study(model: RobotModel, name: str, n_points: int = 100, payload_kg: float = 0.0,
                   params: dict | None = None, controller: str = 'ancf',
                   progress: Progress | None = None) -> TrackResult:
    """Feedforward pressures along trajectory ``name`` and the forward model's errors.

    ``n_points`` samples over one period (``t = k*period/n_points``, the
    closed curve's end point left out).  Each inverse is warm-started from
    the previous one; its solve time is measured.  The pressures are then
    put through a forward solve (warm-started from the inverse's own
    configuration): its end-effector pose against the target gives the
    position and angle errors (angle: between the z-axes, for robots with two
    or more segments).

    ``controller='pcc'`` computes the feedforward pressures with the PCC
    model's inverse instead (:class:`~bellow_ancf_ros.core.model.PccModel`, the paper's baseline);
    the errors are still those of the ANCF forward model at those pressures,
    i.e. what the ANCF model predicts a PCC-based feedforward would do.
    """
    progress = progress or _noop
    if n_points < 1:
        raise ValueError('the trajectory needs at least one point')
    if controller not in ('ancf', 'pcc'):
        raise ValueError(f"controller must be 'ancf' or 'pcc', got {controller!r}")
    cfg = model.cfg
    pcc = PccModel(cfg) if controller == 'pcc' else None
    params = {k: v for k, v in (params or {}).items() if v is not None}
    merged = trajectories.trajectory_parameters(name, cfg, **params)
    period = float(merged['period'])
    t = np.arange(n_points) * period / n_points
    pos, zax = trajectories.trajectory(name, t, config=cfg, **params)
    A = model.A
    P = np.zeros((n_points, A))
    pred = np.full((n_points, 3), np.nan)
    pred_z = np.full((n_points, 3), np.nan)
    perr = np.full(n_points, np.nan)
    aerr = None if zax is None else np.full(n_points, np.nan)
    reach = np.zeros(n_points, bool)
    succ = np.zeros(n_points, bool)
    times = np.zeros(n_points)
    prev = prev_fw = None
    for k in range(n_points):
        if k % max(1, n_points // 20) == 0:
            progress(k, n_points, f'point {k + 1}/{n_points}')
        z = None if zax is None else zax[k]
        t0 = time.perf_counter()
        if pcc is None:
            inv = solve_inverse(model, pos[k], z_axis=z, payload_kg=payload_kg, warm_start=prev)
            times[k] = time.perf_counter() - t0
            P[k] = inv.pressures_pa
            reach[k] = inv.reachable
            ok = bool(inv.success)
            if inv.converged:
                prev = inv
            warm = inv.forward
        else:
            p_k, reach[k], pose = pcc.inverse(pos[k], z_axis=z, warm_lam=prev)
            times[k] = time.perf_counter() - t0
            P[k] = np.clip(p_k, cfg.p_min, cfg.p_max)
            prev, ok = pose.stretch, bool(reach[k])
            warm = prev_fw if k > 0 else None
        fw = solve_forward(model, P[k], payload_kg, warm_start=warm)
        if not fw.converged and warm is not None:
            fw = solve_forward(model, P[k], payload_kg)
        prev_fw = fw if fw.converged else None
        if fw.converged:
            succ[k] = bool(ok and fw.success)
            pred[k] = fw.position
            pred_z[k] = fw.z_axis
            perr[k] = float(np.linalg.norm(fw.position - pos[k]))
            if aerr is not None:
                aerr[k] = angle_between(fw.z_axis, z)
    progress(n_points, n_points, 'done')
    merged['center'] = list(merged['center'])
    return TrackResult(cfg.name, name, float(payload_kg), t, pos, zax, P, pred, pred_z, perr, aerr,
                       reach, succ, times, params=merged, controller=controller)


# ============================================================== stiffness
def _stiffness_row(fw) -> dict:
    """Vertical and lateral tip stiffness [N/m] of a usable equilibrium (else None figures)."""
    if not fw.success:
        return dict(usable=False, vertical_n_per_m=None, lateral_x_n_per_m=None,
                    lateral_y_n_per_m=None, stiffness_n_per_m=None)
    c = tip_compliance(fw)
    C = c.translational_m_per_n
    return dict(usable=True, vertical_n_per_m=float(1.0 / C[2, 2]),
                lateral_x_n_per_m=float(1.0 / C[0, 0]), lateral_y_n_per_m=float(1.0 / C[1, 1]),
                stiffness_n_per_m=c.stiffness_n_per_m)


def stiffness_study(cfg: RobotConfig, payloads_kg: Sequence[float] = (0.0, 0.05, 0.1),
                    n_levels: int = 9, n_elements: int | None = None,
                    progress: Progress | None = None) -> dict[str, Any]:
    """Tip stiffness against equal actuation pressure, per payload.

    Every actuator at the same pressure, ``n_levels`` levels from ``p_min`` to
    ``p_max`` (warm-started forward solves).  A row per payload and level:
    ``payload_kg, pressure_pa, usable`` (a converged, stable equilibrium),
    ``vertical_n_per_m`` (a vertical force over the vertical motion it
    causes, the other force components zero: ``1/C_zz``),
    ``lateral_x_n_per_m``, ``lateral_y_n_per_m`` (``1/C_xx``, ``1/C_yy``) and
    the stiffness matrix ``K = C^{-1}``; None figures where not usable.
    """
    if n_levels < 2:
        raise ValueError(f'n_levels must be at least 2, got {n_levels}')
    progress = progress or _noop
    model = RobotModel(cfg, n_elements)
    levels = np.linspace(cfg.p_min, cfg.p_max, int(n_levels))
    rows = []
    for i, m in enumerate(payloads_kg):
        progress(i, len(payloads_kg), f'payload {m:g} kg')
        prev = None
        for p in levels:
            fw = solve_forward(model, np.full(model.A, p), float(m), warm_start=prev)
            if not fw.converged and prev is not None:
                fw = solve_forward(model, np.full(model.A, p), float(m))
            prev = fw if fw.converged else None
            rows.append(dict(payload_kg=float(m), pressure_pa=float(p), **_stiffness_row(fw)))
    progress(len(payloads_kg), len(payloads_kg), 'done')
    return dict(config=cfg.name, n_elements=model.n, payloads_kg=[float(m) for m in payloads_kg],
                rows=rows)


def stiffness_along_trajectory(model: RobotModel, name: str, n_points: int = 50,
                               payload_kg: float = 0.0, params: dict | None = None) -> dict:
    """Tip stiffness at the feedforward answers along trajectory ``name`` (warm-started).

    Returns ``times_s`` and, per sample, ``vertical_n_per_m``,
    ``lateral_x_n_per_m``, ``lateral_y_n_per_m`` (NaN where the answer is not
    usable) and ``usable``.
    """
    res = tracking_study(model, name, n_points=n_points, payload_kg=payload_kg, params=params)
    keys = ('vertical_n_per_m', 'lateral_x_n_per_m', 'lateral_y_n_per_m')
    out = {k: np.full(n_points, np.nan) for k in keys}
    usable = np.zeros(n_points, bool)
    prev = None
    for k, p in enumerate(res.pressures_pa):
        fw = solve_forward(model, p, payload_kg, warm_start=prev)
        prev = fw if fw.converged else None
        row = _stiffness_row(fw)
        usable[k] = row['usable']
        if usable[k]:
            for key in keys:
                out[key][k] = row[key]
    return dict(config=model.cfg.name, trajectory=name, payload_kg=float(payload_kg),
                times_s=res.times_s, usable=usable, **out)
