"""``bellow-ancf modes``, ``simulate`` and ``identify damping`` (issue 26)."""

import csv
import json

import numpy as np
import pytest

from bellow_ancf_ros import cli
from bellow_ancf_ros.core import DynamicsStatus, GeneralizedAlpha, geometry, solve_forward
from bellow_ancf_ros.core.dynamics import natural_modes, piecewise_linear, sample_motion
from bellow_ancf_ros.core.fit import write_bag

MODE_KEYS = {'frequency_hz', 'damped_frequency_hz', 'damping_ratio', 'direction'}
SAMPLE_KEYS = {'t_s', 'position_m', 'z_axis'}


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err, *fragments):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('bellow-ancf: error: '), err
    for f in fragments:
        assert f in lines[0], err


# -------------------------------------------------------------- modes
def test_modes_json_is_the_cores_lowest_first(capsys, one):
    code, out, err = run(capsys, 'modes', '--pressures-kpa', 30, 0, 0, '--payload-kg', 0.05,
                         '--tip-force-n', 0.1, 0, 0, '--modes', 4, '--json')
    assert code == 0, err
    d = json.loads(out)
    ref = natural_modes(solve_forward(one, [30e3, 0, 0], payload_kg=0.05,
                                      tip_force_n=[0.1, 0, 0]), 4)
    assert len(d['modes']) == 4
    for got, mode in zip(d['modes'], ref.modes):
        assert set(got) == MODE_KEYS
        assert got['frequency_hz'] == pytest.approx(mode.frequency_hz, rel=1e-9)
        assert got['damped_frequency_hz'] == pytest.approx(mode.damped_frequency_hz, rel=1e-9)
        assert got['damping_ratio'] == pytest.approx(mode.damping_ratio, rel=1e-9)
        np.testing.assert_allclose(got['direction'], mode.direction, atol=1e-9)
    f = [m['frequency_hz'] for m in d['modes']]
    assert f == sorted(f)
    assert d['payload_kg'] == 0.05 and d['config'] == 'one_segment'


def test_modes_damping_time_table_and_plot(capsys, tmp_path):
    code, out, _ = run(capsys, 'modes', '--pressures-kpa', 0, 0, 0, '--payload-kg', 0.05,
                       '--damping-time-s', 0.008, '--modes', 2, '--json')
    slow = json.loads(out)
    code, out, _ = run(capsys, 'modes', '--pressures-kpa', 0, 0, 0, '--payload-kg', 0.05,
                       '--modes', 2, '--json')
    default = json.loads(out)
    assert code == 0 and slow['damping_time_s'] == 0.008
    # Kelvin-Voigt: the ratio grows with the retardation time, the frequency does not change
    assert slow['modes'][0]['damping_ratio'] > 1.4 * default['modes'][0]['damping_ratio']
    assert slow['modes'][0]['frequency_hz'] == pytest.approx(
        default['modes'][0]['frequency_hz'], rel=1e-9)
    png = tmp_path / 'modes.png'
    code, out, _ = run(capsys, 'modes', '--config', 'two_segment', '--pressures-kpa',
                       *[0] * 6, '--modes', 4, '--plot', png)
    assert code == 0 and png.stat().st_size > 5000
    assert 'frequency [Hz]' in out and 'damping ratio' in out and '+x' in out


def test_modes_of_an_unstable_equilibrium_is_one_line_exit_1(capsys):
    code, out, err = run(capsys, 'modes', '--config', 'two_segment', '--pressures-kpa',
                         *[0] * 6, '--tip-force-n', 0, 0, -20, '--json')
    assert code == 1 and not out
    assert_one_line_error(err, 'equilibrium')


# ----------------------------------------------------------- simulate
def test_simulate_release_json_csv_plot(capsys, tmp_path, one):
    out_csv, png = tmp_path / 'rel.csv', tmp_path / 'rel.png'
    code, out, err = run(capsys, 'simulate', '--pressures-kpa', 0, 0, 0, '--payload-kg', 0.05,
                         '--release-tip-force-n', 0.3, 0, 0, '--duration-s', 0.3,
                         '--sample-s', 0.01, '--json', '--csv', out_csv, '--plot', png)
    assert code == 0, err
    d = json.loads(out)
    s = d['samples']
    assert len(s) == 31 and all(set(x) == SAMPLE_KEYS for x in s)
    np.testing.assert_allclose([x['t_s'] for x in s], np.arange(31) * 0.01, atol=1e-12)
    held = solve_forward(one, [0, 0, 0], payload_kg=0.05, tip_force_n=[0.3, 0, 0])
    np.testing.assert_allclose(s[0]['position_m'], held.position, atol=1e-12)
    assert s[0]['position_m'][0] > 2e-3 and min(x['position_m'][0] for x in s) < -0.5e-3
    assert d['success'] and d['status'] == 0 and d['max_constraint_violation_m'] < 1e-9
    assert d['check_s'] == 0.01 and 0 < d['energy_end_j'] < d['energy_start_j']   # damped
    assert d['step_s'] == pytest.approx(0.01 / round(0.01 / d['step_s']), rel=1e-12)
    with open(out_csv) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ['t_s', 'x_m', 'y_m', 'z_m', 'zx', 'zy', 'zz', 'p1_kpa', 'p2_kpa',
                       'p3_kpa']
    assert len(rows) == 32
    np.testing.assert_allclose([float(v) for v in rows[-1][1:7]],
                               s[-1]['position_m'] + s[-1]['z_axis'], rtol=1e-15)
    assert png.stat().st_size > 5000


def test_simulate_step_equals_a_constant_pressure_table_and_the_core(capsys, tmp_path, one):
    common = ['simulate', '--pressures-kpa', 0, 0, 0, '--duration-s', 0.1, '--step-s', 0.004,
              '--json']
    code, out, err = run(capsys, *common, '--step-pressures-kpa', 60, 0, 0)
    assert code == 0, err
    step = json.loads(out)
    table = tmp_path / 'p.csv'
    table.write_text('t_s,p1_kpa,p2_kpa,p3_kpa\n0,60,0,0\n5,60,0,0\n')
    code, out, err = run(capsys, *common, '--pressures-csv', table)
    assert code == 0, err
    same = json.loads(out)
    assert same['samples'] == step['samples']
    # and both are the core's integration
    ig = GeneralizedAlpha(one, step_s=0.004)
    ig.start(solve_forward(one, [0, 0, 0]))
    ref = sample_motion(ig, 0.1, pressures_pa=[60e3, 0, 0])
    np.testing.assert_allclose([x['position_m'] for x in step['samples']], ref.positions_m,
                               rtol=0, atol=1e-12)
    # the robot bends away from the pressurised actuator 1 (at +x): the tip moves
    assert abs(step['samples'][-1]['position_m'][0]) > 1e-3


def test_simulate_pressure_table_is_linear_between_rows_and_starts_at_t0(capsys, tmp_path, one):
    table = tmp_path / 'ramp.csv'
    table.write_text('# a ramp\nt_s,p1_kpa,p2_kpa,p3_kpa\n0,10,0,0\n0.05,40,0,0\n')
    code, out, err = run(capsys, 'simulate', '--duration-s', 0.08, '--step-s', 0.004,
                         '--pressures-csv', table, '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['pressures_pa'] == [10e3, 0, 0]          # the start: the table at t = 0
    ig = GeneralizedAlpha(one, step_s=0.004)
    ig.start(solve_forward(one, [10e3, 0, 0]))
    ref = sample_motion(ig, 0.08, pressures_pa=piecewise_linear([0, 0.05],
                                                                [[10e3, 0, 0], [40e3, 0, 0]]))
    np.testing.assert_allclose([x['position_m'] for x in d['samples']], ref.positions_m,
                               rtol=0, atol=1e-12)


def test_a_failed_integration_reports_and_keeps_what_was_computed(capsys, tmp_path,
                                                                  monkeypatch):
    original = GeneralizedAlpha._run

    def fails_late(self, times, steps, lams, load, *args):   # every step from 0.045 s on
        n = int(np.sum(times - steps <= 0.045))
        status, k = original(self, times[:n], steps[:n], lams[:n], load, *args)
        return (status, k) if k < n or n == len(steps) else (DynamicsStatus.STEP_TOO_SMALL, k)

    monkeypatch.setattr(GeneralizedAlpha, '_run', fails_late)
    out_csv = tmp_path / 'partial.csv'
    code, out, err = run(capsys, 'simulate', '--pressures-kpa', 0, 0, 0,
                         '--release-tip-force-n', 0.2, 0, 0, '--duration-s', 0.2,
                         '--sample-s', 0.01, '--json', '--csv', out_csv)
    assert code == 1
    assert_one_line_error(err, 'the integration stopped', 'at t = 0.046 s')  # 2 ms steps
    d = json.loads(out)
    assert not d['success'] and d['status'] == 5 and len(d['samples']) == 6
    assert len(out_csv.read_text().splitlines()) == 7


@pytest.mark.parametrize('argv, says', [
    (['--release-tip-force-n', 0.1, 0, 0, '--step-pressures-kpa', 1, 0, 0], 'not allowed with'),
    (['--release-tip-force-n', 0.1, 0, 0], '--pressures-kpa is required'),
    (['--pressures-kpa', 0, 0, 0, '--step-pressures-kpa', 1, 0], 'expected 3 pressures'),
    (['--pressures-kpa', 0, 0, 0], 'one of the arguments'),
])
def test_simulate_bad_input_is_one_line(capsys, argv, says):
    code, _, err = run(capsys, 'simulate', '--duration-s', 0.1, *argv)
    assert code == 2
    assert_one_line_error(err, says)


def test_simulate_bad_pressure_table_names_the_line(capsys, tmp_path):
    table = tmp_path / 'bad.csv'
    table.write_text('t_s,p1_kpa,p2_kpa,p3_kpa\n0,10,0,0\n0,20,0,0\n')
    code, _, err = run(capsys, 'simulate', '--duration-s', 0.1, '--pressures-csv', table)
    assert code == 2
    assert_one_line_error(err, 'line 3', 'does not increase')
    table.write_text('t,p1\n0,1\n')
    code, _, err = run(capsys, 'simulate', '--duration-s', 0.1, '--pressures-csv', table)
    assert code == 2
    assert_one_line_error(err, 'expected the header t_s,p1_kpa,p2_kpa,p3_kpa')


# --------------------------------------------------- identify damping
DAMPING_TIME_S = 0.008


def ring_down(model, pressures_pa, payload_kg, force_n, duration_s, sample_s=1 / 120):
    """A simulated release at damping time DAMPING_TIME_S, sampled like a mocap system."""
    fw = solve_forward(model, pressures_pa, payload_kg=payload_kg, tip_force_n=force_n)
    ig = GeneralizedAlpha(model, damping_time_s=DAMPING_TIME_S)
    ig.start_released(fw)
    # half a second at rest before the release: a recording starts before it
    run_ = sample_motion(ig, duration_s, sample_s=sample_s, pressures_pa=pressures_pa)
    assert run_.success
    t = np.concatenate([np.arange(-0.5, 0, sample_s), run_.times_s])
    x = np.concatenate([np.repeat(run_.positions_m[:1], len(t) - len(run_.times_s), 0),
                        run_.positions_m])
    return t + 10.0, x     # a clock that does not start at 0


def write_stream_csv(path, t, x, pressures_pa=None):
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        n_p = 0 if pressures_pa is None else len(pressures_pa)
        w.writerow(['t_s', 'x_m', 'y_m', 'z_m', 'qx', 'qy', 'qz', 'qw']
                   + [f'p{i + 1}_kpa' for i in range(n_p)])
        for ti, xi in zip(t, x):
            w.writerow([ti, *xi, 0, 0, 0, 1]
                       + ([] if pressures_pa is None else list(np.asarray(pressures_pa) / 1e3)))


def test_identify_damping_recovers_the_damping_time_from_a_csv(capsys, tmp_path, one):
    t, x = ring_down(one, [0, 0, 0], 0.05, [0.5, 0.0, 0.0], 1.5)
    rec = tmp_path / 'release.csv'
    write_stream_csv(rec, t, x, [0, 0, 0])
    png = tmp_path / 'fit.png'
    code, out, err = run(capsys, 'identify', 'damping', '--csv', rec, '--payload-kg', 0.05,
                         '--json', '--plot', png)
    assert code == 0, err
    d = json.loads(out)
    assert d['damping_time_s'] == pytest.approx(DAMPING_TIME_S, rel=0.10)
    mode = natural_modes(solve_forward(one, [0, 0, 0], payload_kg=0.05), 1,
                         damping_time_s=DAMPING_TIME_S).first
    assert d['frequency_hz'] == pytest.approx(mode.frequency_hz, rel=0.01)
    assert d['damping_ratio'] == pytest.approx(mode.damping_ratio, rel=0.10)
    # the window: the motion starts at the release (t = 10 s), the fit half a period later
    assert 10.0 <= d['t_motion_s'] < 10.03
    assert d['t_start_s'] == pytest.approx(d['t_motion_s'] + 0.5 / mode.damped_frequency_hz,
                                           abs=0.01)
    assert d['pressures_from'].startswith('the recording') and png.stat().st_size > 5000
    # the text report and an explicit window
    code, out, err = run(capsys, 'identify', 'damping', '--csv', rec, '--payload-kg', 0.05,
                         '--t-start-s', 10.1, '--t-end-s', 11.2)
    assert code == 0, err
    assert 'damping_time_s' in out and 'first mode' in out
    # the model is the recording's robot: its first mode is known, for the robot file
    line = next(w for w in out.splitlines() if w.startswith('first_mode_err'))
    assert abs(float(line.split()[1].rstrip(';'))) < 0.01
    assert 'dynamics.first_mode_error' in line and '1.5 periods' in line
    assert abs(d['frequency_error']) < 0.01


def test_simulate_csv_of_a_pressure_step_is_a_recording_identify_damping_reads(capsys,
                                                                               tmp_path):
    """The round trip: ``simulate --csv`` of a step, its pressures taken from the file."""
    rec = tmp_path / 'step.csv'
    code, _, err = run(capsys, 'simulate', '--pressures-kpa', 0, 0, 0, '--payload-kg', 0.05,
                       '--step-pressures-kpa', 40, 0, 0, '--duration-s', 1.0, '--sample-s',
                       0.005, '--damping-time-s', DAMPING_TIME_S, '--csv', rec)
    assert code == 0, err
    code, out, err = run(capsys, 'identify', 'damping', '--csv', rec, '--payload-kg', 0.05,
                         '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['damping_time_s'] == pytest.approx(DAMPING_TIME_S, rel=0.02)
    np.testing.assert_allclose(d['pressures_pa'], [40e3, 0, 0])


def test_identify_damping_under_mocap_noise(capsys, tmp_path, one):
    """0.15 mm noise, 120 Hz, a release from 9 mm: 30 noise seeds gave -5 % to +4 %."""
    t, x = ring_down(one, [0, 0, 0], 0.05, [1.0, 0.0, 0.0], 1.5)
    x = x + np.random.default_rng(26).normal(0.0, 0.15e-3, x.shape)
    rec = tmp_path / 'noisy.csv'
    write_stream_csv(rec, t, x)       # no pressures in the file: given on the command line
    code, out, err = run(capsys, 'identify', 'damping', '--csv', rec, '--payload-kg', 0.05,
                         '--pressures-kpa', 0, 0, 0, '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['damping_time_s'] == pytest.approx(DAMPING_TIME_S, rel=0.10)
    assert d['rms_residual_m'] == pytest.approx(0.15e-3, rel=0.2)


def test_identify_damping_two_segments_from_a_bag(capsys, tmp_path, two):
    p = np.array([20e3, 0, 0, 0, 10e3, 0])
    t, x = ring_down(two, p, 0.02, [0.0, 0.02, 0.0], 3.0, sample_s=1 / 60)
    bag = tmp_path / 'release_bag'
    quat = geometry.quaternion_from_rotation(np.eye(3))
    write_bag(bag, [(t[0], p), (t[0] + 0.2, p)], [(ti, xi, quat) for ti, xi in zip(t, x)])
    code, out, err = run(capsys, 'identify', 'damping', '--config', 'two_segment', '--bag', bag,
                         '--payload-kg', 0.02, '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['damping_time_s'] == pytest.approx(DAMPING_TIME_S, rel=0.10)
    np.testing.assert_allclose(d['pressures_pa'], p)
    assert abs(d['direction'][1]) > 0.99


def test_identify_damping_bad_recordings(capsys, tmp_path):
    rec = tmp_path / 'still.csv'
    write_stream_csv(rec, np.arange(100) * 0.01, np.zeros((100, 3)))
    code, _, err = run(capsys, 'identify', 'damping', '--csv', rec, '--pressures-kpa', 0, 0, 0)
    assert code == 2
    assert_one_line_error(err, 'no free vibration', 'does not move')
    rec.write_text('t_s,x_m,y_m\n0,0,0\n')
    code, _, err = run(capsys, 'identify', 'damping', '--csv', rec)
    assert code == 2
    assert_one_line_error(err, 'no column z_m')
    code, _, err = run(capsys, 'identify', 'damping', '--bag', tmp_path / 'nothing')
    assert code == 2
    assert_one_line_error(err, 'no such bag directory')


def test_identify_damping_needs_the_pressures(capsys, tmp_path, one):
    t, x = ring_down(one, [0, 0, 0], 0.0, [0.3, 0.0, 0.0], 0.6)
    rec = tmp_path / 'np.csv'
    write_stream_csv(rec, t, x)
    code, _, err = run(capsys, 'identify', 'damping', '--csv', rec)
    assert code == 2
    assert_one_line_error(err, 'give --pressures-kpa')


@pytest.mark.parametrize('argv', [['modes'], ['simulate'], ['identify', 'damping']])
def test_help(capsys, argv):
    code, out, _ = run(capsys, *argv, '--help')
    assert code == 0 and '--json' in out and '--plot' in out
