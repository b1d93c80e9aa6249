"""``bellow-ancf identify creep``: the creep from a recorded pressure step (CSV and bag).

The recordings are the simulated robot's (its own robot file, realistic
regulators, creep, dynamics and motion capture: 0.15 mm noise, outliers,
dropouts) stepped from vent to 80 kPa on actuator 1 and held for 20 s, on a
clock that starts at 100 s.
"""

import csv
import json

import numpy as np
import pytest

from bellow_ancf_ros.core import geometry
from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.fit import POSE_STREAM_COLUMNS, write_bag
from test_cli import assert_one_line_error, run   # (the CLI tests' helpers)

CREEP_FRACTION = 0.12
CREEP_TIME_CONSTANT_S = 2.5
CLOCK_S = 100.0
STEP_S = 1.0
STEP_PA = np.array([80e3, 0.0, 0.0])


def record_step(after_s=20.0, step=True, seed=4):
    """Mocap samples ``(t, x, pressures)`` of the simulated robot around a step at STEP_S."""
    e = PlantEffects(creep_fraction=CREEP_FRACTION, creep_time_constant_s=CREEP_TIME_CONSTANT_S)
    robot = SimulatedRobot(effects=e, seed=seed)
    dt = 1.0 / robot.auto_physics_rate_hz
    times, positions = [], []
    t_next = robot.mocap.period_s
    commanded = not step
    while robot.time_s < STEP_S + after_s:
        if not commanded and robot.time_s >= STEP_S - 1e-9:
            robot.command(STEP_PA)
            commanded = True
        robot.step(dt)
        while t_next <= robot.time_s + 1e-12:
            sample = robot.capture(t_next)
            if sample is not None:
                times.append(sample.captured_s)
                positions.append(sample.position)
            t_next += robot.mocap.period_s
    t = np.array(times)
    p = np.where((t >= STEP_S)[:, None] & step, STEP_PA, 0.0)   # the command in effect
    return t + CLOCK_S, np.array(positions), p


def write_stream_csv(path, t, x, p=None):
    """A pose-stream CSV file (POSE_STREAM_COLUMNS, a quaternion, the pressures in kPa)."""
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(list(POSE_STREAM_COLUMNS) + ['qx', 'qy', 'qz', 'qw']
                   + ([] if p is None else [f'p{i + 1}_kpa' for i in range(p.shape[1])]))
        for k, (ti, xi) in enumerate(zip(t, x)):
            w.writerow([repr(float(ti)), *(repr(float(v)) for v in xi), 0, 0, 0, 1]
                       + ([] if p is None else [repr(float(v)) for v in p[k] / 1e3]))


@pytest.fixture(scope='module')
def recording():
    return record_step()


@pytest.fixture
def step_csv(tmp_path, recording):
    path = tmp_path / 'step.csv'
    write_stream_csv(path, *recording)
    return path


def test_recovers_the_creep_from_a_csv_with_pressures(capsys, tmp_path, step_csv):
    png = tmp_path / 'creep.png'
    code, out, err = run(capsys, 'identify', 'creep', '--csv', step_csv, '--json',
                         '--plot', png)
    assert code == 0, err
    d = json.loads(out)
    assert d['creep_fraction'] == pytest.approx(CREEP_FRACTION, abs=0.02)
    assert d['creep_time_constant_s'] == pytest.approx(CREEP_TIME_CONSTANT_S, rel=0.15)
    # the step from the recorded pressures: the first pose after the command
    assert d['t_step_from'] == "the recording's pressures"
    assert CLOCK_S + STEP_S <= d['t_step_s'] < CLOCK_S + STEP_S + 0.01
    assert d['pressures_before_pa'] == [0.0, 0.0, 0.0]
    assert d['pressures_after_pa'] == pytest.approx(STEP_PA.tolist())
    assert d['displacement_m'] == pytest.approx(11.1e-3, rel=0.02)
    assert d['noise_m'] == pytest.approx(0.15e-3, rel=0.3)
    assert d['outliers'] >= 1 and d['plot'] == str(png) and png.stat().st_size > 5000


def test_the_report_ends_with_the_values_and_where_they_go(capsys, step_csv):
    code, out, err = run(capsys, 'identify', 'creep', '--csv', step_csv, '--settle-s', 0.8)
    assert code == 0, err
    last = out.strip().splitlines()[-1]
    assert last.startswith('creep_fraction 0.1')
    assert last.endswith('inverse node parameters creep_fraction, creep_time_constant_s')
    c, t = (float(v.rstrip(':,')) for v in last.split()[1:4:2])
    assert c == pytest.approx(CREEP_FRACTION, abs=0.02)
    assert t == pytest.approx(CREEP_TIME_CONSTANT_S, rel=0.15)
    assert '0 0 0 -> 80 0 0 kPa' in out and '(0.8 s after the step)' in out


def test_recovers_the_creep_from_a_bag(capsys, tmp_path, recording):
    t, x, _ = recording
    quat = geometry.quaternion_from_rotation(np.eye(3))
    # the command republished at 10 Hz, stepped at the step
    cmd_t = np.arange(t[0], t[-1], 0.1)
    cmd_t = np.sort(np.append(cmd_t, CLOCK_S + STEP_S))
    commands = [(ti, STEP_PA if ti >= CLOCK_S + STEP_S else np.zeros(3)) for ti in cmd_t]
    bag = tmp_path / 'step_bag'
    write_bag(bag, commands, [(ti, xi, quat) for ti, xi in zip(t, x)], storage='mcap')
    code, out, err = run(capsys, 'identify', 'creep', '--bag', bag, '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['t_step_s'] == pytest.approx(CLOCK_S + STEP_S, abs=1e-6)
    assert d['creep_fraction'] == pytest.approx(CREEP_FRACTION, abs=0.02)
    assert d['creep_time_constant_s'] == pytest.approx(CREEP_TIME_CONSTANT_S, rel=0.15)


def test_without_pressures_the_step_time_is_needed(capsys, tmp_path, recording):
    t, x, _ = recording
    rec = tmp_path / 'poses.csv'
    write_stream_csv(rec, t, x)
    code, _, err = run(capsys, 'identify', 'creep', '--csv', rec)
    assert code == 2
    assert_one_line_error(err, 'no pressures', 'give --t-step-s')
    code, out, err = run(capsys, 'identify', 'creep', '--csv', rec, '--t-step-s',
                         CLOCK_S + STEP_S, '--json')
    assert code == 0, err
    d = json.loads(out)
    assert d['t_step_from'] == '--t-step-s' and d['pressures_before_pa'] is None
    assert d['creep_fraction'] == pytest.approx(CREEP_FRACTION, abs=0.02)


def test_refuses_a_recording_too_short_for_the_creep(capsys, step_csv):
    code, _, err = run(capsys, 'identify', 'creep', '--csv', step_csv, '--t-end-s',
                       CLOCK_S + STEP_S + 3.0)
    assert code == 2
    assert_one_line_error(err, 'no creep from this recording',
                          'record at least ~4 time constants after the step')


def test_refuses_a_robot_that_does_not_move(capsys, tmp_path):
    t, x, _ = record_step(after_s=4.0, step=False)
    rec = tmp_path / 'still.csv'
    write_stream_csv(rec, t, x, np.zeros((len(t), 3)))
    code, _, err = run(capsys, 'identify', 'creep', '--csv', rec)
    assert code == 2
    assert_one_line_error(err, "the recording's pressures", 'never change', 'give --t-step-s')
    code, _, err = run(capsys, 'identify', 'creep', '--csv', rec, '--t-step-s', CLOCK_S + 1.0)
    assert code == 2
    assert_one_line_error(err, 'no creep from this recording', 'the tip does not move')


def test_bad_recordings_and_options(capsys, tmp_path):
    rec = tmp_path / 'bad.csv'
    rec.write_text('t_s,x_m,y_m\n0,0,0\n')
    code, _, err = run(capsys, 'identify', 'creep', '--csv', rec)
    assert code == 2
    assert_one_line_error(err, '--csv', 'no column z_m')
    code, _, err = run(capsys, 'identify', 'creep', '--bag', tmp_path / 'nothing')
    assert code == 2
    assert_one_line_error(err, '--bag', 'no such bag directory')
    code, _, err = run(capsys, 'identify', 'creep', '--csv', rec, '--settle-s', -1)
    assert code == 2
    assert_one_line_error(err, '--settle-s')


def test_help(capsys):
    code, out, _ = run(capsys, 'identify', 'creep', '--help')
    assert code == 0 and '--json' in out and '--plot' in out and '--t-step-s' in out
    code, out, _ = run(capsys, 'identify', '--help')
    assert code == 0 and 'creep' in out
