"""Calibration benchmark (`make bench-calibrate`): time of `calibrate` on ~200 samples.

A synthetic recording of a mismatched robot (pitch radius +4 %, D_a -5 %,
stiffness +6 %, top-plate masses +5 %) seen by a mocap system whose frame is
off by centimetres and degrees, 0.15 mm / 0.1 deg noise; the default fit
(pitch radius, D_a, D_eff, stiffness scale) plus the 6 frame parameters.
Target: under a minute for about 200 samples.  Timing is wall-clock on a
shared machine; the CPU time says how much of it was ours.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bellow_ancf_ros.core import calibrate, limit_blas_threads, load_robot, robot_from_dict
from bellow_ancf_ros.core import parameter_keys as pk
from bellow_ancf_ros.core.fit import excitation_sequence, simulate_recording

TARGET_S = 60.0


def _case(name: str, samples: int):
    cfg = load_robot(name)
    d = cfg.to_dict()
    changes = {'segments[*].pitch_radius_mm': 1.04, 'actuator.d_a_mm': 0.95,
               pk.STIFFNESS_SCALE: 1.06, 'segments[*].top_plate_mass_kg': 1.05}
    true = robot_from_dict(pk.with_values(d, list(changes),
                                          [pk.get_value(d, k) * f for k, f in changes.items()]))
    schemes = excitation_sequence(cfg, 3, 0)
    P = excitation_sequence(cfg, 3, max(samples - len(schemes), 0), seed=1)
    rec, _, _ = simulate_recording(true, P, (0.031, -0.018, 0.052), np.radians([3, -2, 5]),
                                   0.15e-3, np.radians(0.1), seed=2)
    wall, cpu = time.perf_counter(), time.process_time()
    res = calibrate(cfg, rec)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f'{name:12s} {len(rec):4d} samples  wall {wall:6.1f} s  cpu {cpu:6.1f} s  '
          f'({"meets" if wall < TARGET_S else "MISSES"} the {TARGET_S:.0f} s target)  '
          f'{res.nfev} evaluations, RMSE {res.rmse_before_mm:.3f} -> {res.rmse_after_mm:.3f} mm',
          flush=True)


def main(argv=None) -> None:
    """Run the cases."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--samples', type=int, default=200)
    ap.add_argument('--robots', nargs='+', default=['one_segment', 'two_segment'])
    args = ap.parse_args(argv)
    limit_blas_threads()
    for name in args.robots:
        _case(name, args.samples)


if __name__ == '__main__':
    main()
