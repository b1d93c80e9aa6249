"""Demonstration of the model (``make demo-offline``, ``python -m bellow_ancf_ros.demos.offline``).

Solves forward and inverse problems on the shipped one- and two-segment
robots and prints readable tables with timings (a few seconds in total).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from ..cli.output import count, number
from ..core import RobotModel, load_robot, solve_forward, solve_inverse
from ..core.geometry import angle_between


def _timed(func, *args, **kwargs):
    start = time.perf_counter()
    result = func(*args, **kwargs)
    return result, time.perf_counter() - start


def _kpa(pressures_pa) -> str:
    return ' '.join(number(p / 1e3, '7.1f') for p in pressures_pa)


def _mm(position_m) -> str:
    return ' '.join(number(v * 1e3, '7.2f') for v in position_m)


def _tilt_deg(z_axis) -> float:
    """Bending angle: angle between the end-effector z-axis and the base z-axis."""
    return float(np.degrees(angle_between(z_axis, [0.0, 0.0, 1.0])))


def _state(result) -> str:
    if not result.converged:
        return 'NOT CONVERGED'
    return 'ok' if result.stable else 'UNSTABLE'


def _limits(active) -> str:
    names = [f'{i + 1}:{"max" if a > 0 else "min"}' for i, a in enumerate(active) if a]
    return ','.join(names) if names else '-'


def _as_expected(inv, reachable: bool) -> bool:
    """A reachable target must be met (1 um, 1 urad); an unreachable one flagged, at a limit."""
    if not np.all(np.isfinite(inv.pressures_pa)) or not inv.converged:
        return False
    if reachable:
        # a target on the workspace boundary (pressures at a limit) may be met to within the
        # box solver's accuracy without the strict ``reachable`` flag: judge by the errors
        return inv.position_error_m < 1e-6 and (inv.angle_error_rad or 0.0) < 1e-6
    return not inv.reachable and bool(np.any(inv.active_limits))


def _header(title: str, model: RobotModel) -> None:
    cfg = model.cfg
    print()
    print(f'=== {title}: {cfg.name}, {cfg.n_segments} segment(s), {model.A} actuators, '
          f'{model.n} elements per actuator, pressure limits [{cfg.p_min / 1e3:g}, '
          f'{cfg.p_max / 1e3:g}] kPa')


class _Demo:
    """Runs the cases, keeps going after a failure, remembers whether any failed."""

    def __init__(self):
        self.failures = 0

    def run(self, label, func, *args, **kwargs):
        try:
            return _timed(func, *args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - a demo reports and carries on
            self.failures += 1
            print(f'  {label}: FAILED with {type(exc).__name__}: {str(exc)[:200]}')
            return None, None

    def forward_table(self, model, cases):
        width = 8 * model.A - 1
        print('\n  forward: pressures -> pose')
        print(f'  {"case":<20} {"payload":>7}  {"pressures [kPa]":<{width}}  '
              f'{"tip x y z [mm]":<23}  {"tilt":>6}  {"iter":>4}  {"time":>7}  state')
        results = []
        for label, pressures_kpa, payload in cases:
            fw, dt = self.run(label, solve_forward, model, np.asarray(pressures_kpa) * 1e3,
                              payload_kg=payload)
            results.append(fw)
            if fw is None:
                continue
            if not fw.success:
                self.failures += 1
            print(f'  {label:<20} {payload:5.3f}kg  {_kpa(fw.pressures_pa):<{width}}  '
                  f'{_mm(fw.position):<23}  {_tilt_deg(fw.z_axis):5.1f}d  {fw.iterations:4d}  '
                  f'{dt * 1e3:5.0f}ms  {_state(fw)}')
        return results

    def inverse_table(self, model, cases, expect_reachable):
        multi = model.cfg.n_segments >= 2
        print('\n  inverse: target -> pressures (cold start)')
        print(f'  {"case":<20} {"target x y z [mm]":<23}  {"pressures [kPa]":<{8 * model.A - 1}}  '
              f'{"reach":>5}  {"pos err":>9}  {"ang err":>9}  {"limits":<12}  {"time":>7}')
        results = []
        for (label, position, z_axis), expected in zip(cases, expect_reachable):
            inv, dt = self.run(label, solve_inverse, model, position,
                               z_axis=z_axis if multi else None)
            results.append(inv)
            if inv is None:
                continue
            if not _as_expected(inv, expected):
                self.failures += 1
            ang = '-' if inv.angle_error_rad is None else f'{np.degrees(inv.angle_error_rad):.2e}d'
            width = 8 * model.A - 1
            print(f'  {label:<20} {_mm(position):<23}  {_kpa(inv.pressures_pa):<{width}}  '
                  f'{"yes" if inv.reachable else "no":>5}  {inv.position_error_m * 1e3:7.2e}mm  '
                  f'{ang:>9}  {_limits(inv.active_limits):<12}  {dt * 1e3:5.0f}ms')
            if not inv.reachable:
                print(f'  {"":<20} -> {inv.message}')
        return results


def main(argv=None) -> int:
    """Run the demonstration; return 0 if every case behaved as expected, 1 otherwise."""
    start = time.perf_counter()
    demo = _Demo()
    print('bellow_ancf_ros demo: kinetostatic ANCF model of bellow-shaped soft continuum robots')
    print('(tip = end-effector point; tilt = angle between tip z-axis and base z-axis; '
          'actuator 1 lies on the base +x axis)')

    # ---- one segment
    model = RobotModel(load_robot('one_segment'))
    _header('one-segment robot', model)
    extreme, _, full, _ = demo.forward_table(model, [
        ('extreme 150/-50/-50', (150, -50, -50), 0.0),
        ('extreme 150/-50/-50', (150, -50, -50), 0.05),
        ('equal 150/150/150', (150, 150, 150), 0.0),
        ('equal 150/150/150', (150, 150, 150), 0.05),
    ])
    source = (120.0, 20.0, -30.0)
    fw, _ = demo.run('forward for the inverse target', solve_forward, model,
                     np.asarray(source) * 1e3)
    cases, expected = [], []
    if fw is not None:
        cases.append(('from forward', fw.position, None))
        expected.append(True)
    if full is not None:
        cases.append(('20 mm too high', full.position + [0.0, 0.0, 0.02], None))
        expected.append(False)
    kpa = '/'.join(f'{p:g}' for p in source)
    print(f'\n  inverse targets: the tip of a forward solve at {kpa} kPa '
          '(reachable), and 20 mm above the tip at full pressure (unreachable)')
    demo.inverse_table(model, cases, expected)

    # ---- two segments
    model = RobotModel(load_robot('two_segment'))
    _header('two-segment robot', model)
    results = demo.forward_table(model, [
        ('120/-50/-50/0/0/0', (120, -50, -50, 0, 0, 0), 0.0),
        ('40/0/-20/30/0/10', (40, 0, -20, 30, 0, 10), 0.0),
    ])
    cases = [(f'pose of {label}', f.position, f.z_axis)
             for label, f in zip(('120/-50/-50/..', '40/0/-20/..'), results) if f is not None]
    print('\n  inverse targets: position and z-axis of the forward solves '
          '(the first one lies on the workspace\n  boundary: two pressures at p_min).  '
          'Six stretches, five target equations: '
          'the inverse returns\n  the solution closest to mid-range pressures, so it may differ '
          'from the pressures of the forward solve.')
    demo.inverse_table(model, cases, [True] * len(cases))

    total = time.perf_counter() - start
    print(f'\ndemo finished in {total:.1f} s'
          + ('' if not demo.failures
             else f'; {count(demo.failures, "case")} did not behave as expected'))
    return 0 if demo.failures == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
