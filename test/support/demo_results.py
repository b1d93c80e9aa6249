"""A synthetic ``make demo`` results file (demos/closed_loop.py's layout), without ROS.

Built through the demo's own record functions from made-up analyses
(``analyse``'s layout): every case at every speed, the feedforward runs
``ff_mm`` off the target, the closed loop ``cl_mm`` off (``cl_10x_mm`` at
10x), every held target ``held_mm`` off except the 50 g case at 10x
(``held_50g_mm``); ``n`` samples per run.
"""

import numpy as np

from bellow_ancf_ros.demos import closed_loop as demo


def analysis(period_s, err_mm, held_mm, n=2400):
    """One made-up run: a circle, the robot ``err_mm`` off it (wobbling at 3x the path)."""
    t = np.linspace(0.0, period_s, n, endpoint=False)
    ph = 2 * np.pi * t / period_s
    target = np.column_stack([0.02 * np.cos(ph), 0.02 * np.sin(ph), np.full(n, 0.209)])
    off = err_mm * 1e-3 * np.column_stack([np.cos(3 * ph), np.sin(3 * ph), 0 * ph])
    return {'n_targets': n, 'n_measured': n, 't': t, 'target': target,
            'measured': target + off, 'pos_err': np.linalg.norm(off, axis=1),
            'ang_err': np.full(n, np.radians(0.4 * err_mm)), 'steady_mm': held_mm,
            'steady_deg': 0.3 * held_mm, 'model_rms_mm': 1.2, 'outliers': 3,
            'step_after_outlier_kpa': 0.5, 'step_normal_p99_kpa': 0.6,
            'step_normal_max_kpa': 0.7, 'dropouts': 1,
            'error_2s_after_dropouts_mm': [0.05], 'n_commands': 1000, 'safe': True,
            'vent': [0.0] * 6, 'levels': [100, 2, 0]}


def results(ff_mm=5.0, cl_mm=0.08, cl_10x_mm=0.3, held_mm=0.05, held_50g_mm=0.61, n=2400,
            zvd_mm=0.038, date='2026-12-04T03:10:00+00:00'):
    """A whole results file's content (``main`` writes the same keys)."""
    cases = []
    for col in demo.columns():
        res = {}
        for mode in col.case.modes:
            err = ff_mm if mode != 'integral' else (cl_10x_mm if col.speed == 10 else cl_mm)
            held = (held_50g_mm if mode == 'integral' and col.case.payload_kg
                    and col.speed == 10 else held_mm)
            res[mode] = analysis(col.period_s, err, held, n)
        cases.append(demo.column_record(col, res))
    step = demo.step_record({'ran': True, 'shaper': '',
                             'runs': {'none': {'swing_mm': 2.49, 'before_mm': 0.01},
                                      'zvd': {'swing_mm': zvd_mm, 'before_mm': 0.01},
                                      'closed': {'swing_mm': 0.05, 'before_mm': 0.01,
                                                 'overshoot_mm': 0.21, 'late_mm': 0.12}}})
    return {'format': demo.RESULTS_FORMAT, 'date': date, 'date_end': date, 'wall_s': 863.0,
            'machine': {'cpus': 2, 'load_start': [0.12, 0.2, 0.3], 'load_end': [1.9, 1.8, 1.2],
                        'platform': 'Linux', 'python': '3.12'},
            'options': {'plant': 'realistic', 'speeds': [1.0, 4.0, 10.0],
                        'cases': ['one_segment', 'two_segment'], 'period_scale': 1.0,
                        'lead_in_s': 2.0, 'hold_s': 4.0, 'spin_up_s': 5.0, 'seed': 1,
                        'sequential': True, 'goals_checked': True, 'step': True},
            'paper': demo.PAPER, 'passed': all(c['met'] for c in cases) and step['met'],
            'cases': cases, 'step': step}
