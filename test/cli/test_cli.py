"""Tests of the command-line interface ``bellow-ancf`` and of the demo.

Most tests run the CLI in-process through ``main([...])``; a few run it as a
real subprocess (``python -m bellow_ancf_ros.cli``) to check the exit status,
the streams and the module entry point.
"""

import json
import math
import os
from pathlib import Path
import re
import subprocess
import sys
import types

import numpy as np
import pytest

from bellow_ancf_ros import cli
from bellow_ancf_ros.demos import offline as demo
from bellow_ancf_ros.cli import solve as cli_solve
from bellow_ancf_ros.core import solve_forward

REPO = Path(__file__).resolve().parents[2]

FORWARD_KEYS = {
    'position_m', 'rotation', 'z_axis', 'stretch', 'pressures_pa', 'payload_kg', 'tip_force_n',
    'converged',
    'stable', 'status', 'message', 'iterations', 'residual_norm',
}
INVERSE_KEYS = FORWARD_KEYS | {
    'success', 'reachable', 'position_error_m', 'angle_error_rad', 'active_limits',
    'target_position_m', 'target_z_axis',
}
ONE_SEG_LIMITS_PA = (-50e3, 150e3)
TWO_SEG_LIMITS_PA = (-50e3, 120e3)


# ----------------------------------------------------------------- helpers
def run(capsys, *argv):
    """``main(argv)`` in-process: (exit status, stdout, stderr)."""
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def json_lines(text):
    """Parse JSON Lines strictly (NaN/Infinity are not JSON)."""
    def no_constants(name):
        raise AssertionError(f'non-standard JSON constant {name}')
    return [json.loads(line, parse_constant=no_constants) for line in text.splitlines() if line]


def one_json(text):
    records = json_lines(text)
    assert len(records) == 1, text
    return records[0]


def assert_one_line_error(err, *fragments):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith('bellow-ancf: error: '), err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, err)


def nums(values):
    """Command-line text of numbers, exact (repr of a Python float round-trips)."""
    return [repr(float(v)) for v in values]


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def subprocess_env():
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(REPO)] + [p for p in [env.get('PYTHONPATH')] if p])
    return env


def run_subprocess(*argv, stdin=None):
    return subprocess.run(
        [sys.executable, '-m', 'bellow_ancf_ros.cli', *[str(a) for a in argv]],
        cwd=REPO, env=subprocess_env(), input=stdin, capture_output=True, text=True, timeout=300,
    )


# ----------------------------------------------------------------- forward
def test_forward_equal_pressures_tip_on_axis(capsys):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', 100, 100, 100, '--json')
    assert code == 0, err
    d = one_json(out)
    assert set(d) == FORWARD_KEYS
    x, y, z = d['position_m']
    assert abs(x) < 1e-9 and abs(y) < 1e-9
    assert 0.0963 < z < 0.12          # stretched beyond l0 by 100 kPa
    assert d['z_axis'] == pytest.approx([0, 0, 1], abs=1e-9)
    assert np.allclose(d['rotation'], np.eye(3), atol=1e-9)
    assert d['pressures_pa'] == pytest.approx([100e3] * 3)
    assert d['stretch'][0] > 1 and d['stretch'] == pytest.approx([d['stretch'][0]] * 3)
    assert d['converged'] is True and d['stable'] is True
    assert d['status'] == 0 and isinstance(d['message'], str)
    assert d['payload_kg'] == 0.0
    assert d['residual_norm'] < 1e-8


def test_forward_bends_away_from_actuator_1(capsys):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', 150, -50, -50, '--json')
    assert code == 0, err
    d = one_json(out)
    x, y, z = d['position_m']
    assert x < -0.01                  # actuator 1 is on +x: the robot bends towards -x
    assert abs(y) < 1e-9
    assert d['z_axis'][0] < -0.1 and abs(d['z_axis'][1]) < 1e-9
    assert d['stretch'][0] > 1 > d['stretch'][1]
    assert d['stretch'][1] == pytest.approx(d['stretch'][2])


def test_forward_payload_and_elements_options(capsys):
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', 100, 100, 100, '--payload-kg', 0.05,
                       '--elements', 3, '--json')
    assert code == 0
    loaded = one_json(out)
    assert loaded['payload_kg'] == 0.05
    _, out, _ = run(capsys, 'forward', '--pressures-kpa', 100, 100, 100, '--elements', 3, '--json')
    free = one_json(out)
    assert loaded['position_m'][2] < free['position_m'][2]   # gravity compresses the robot


def test_forward_human_summary(capsys):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', 150, -50, -50)
    assert code == 0 and err == ''
    assert 'mm' in out and 'kPa' in out and 'z-axis' in out and 'stretch' in out
    assert 'converged      yes' in out and 'stable yes' in out
    assert '150.000' in out and '-50.000' in out
    assert '-21.4' in out            # tip x in mm
    assert not out.lstrip().startswith('{')


def test_forward_two_segment_config_by_name_and_path(capsys):
    argv = ['--pressures-kpa', 120, -50, -50, 0, 0, 0, '--json']
    code, out, err = run(capsys, 'forward', '--config', 'two_segment', *argv)
    assert code == 0, err
    by_name = one_json(out)
    code, out, err = run(capsys, 'forward', '--config', REPO / 'config' / 'two_segment.yaml',
                         *argv)
    assert code == 0, err
    assert one_json(out)['position_m'] == pytest.approx(by_name['position_m'], abs=1e-12)
    assert by_name['position_m'][0] < -0.02 and len(by_name['stretch']) == 6


def test_forward_not_converged_prints_result_and_exits_1(capsys, monkeypatch):
    real = cli_solve.solve_forward

    def failing(*args, **kwargs):
        fw = real(*args, **kwargs)
        fw.converged, fw.status, fw.message = False, 3, 'did not converge (test)'
        fw.residual_norm = float('nan')
        return fw

    monkeypatch.setattr(cli_solve, 'solve_forward', failing)
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', 0, 0, 0, '--json')
    assert code == 1
    d = one_json(out)
    assert d['converged'] is False and d['residual_norm'] is None   # NaN -> null


# ------------------------------------------------------------- CSV replay
def test_forward_csv_replay_with_malformed_row(capsys, tmp_path):
    path = write(tmp_path, 'p.csv',
                 'p1_kpa,p2_kpa,p3_kpa\n150,-50,-50\n140,oops,-50\n100,20,-30\n')
    code, out, err = run(capsys, 'forward', '--pressures-csv', path, '--json')
    assert code == 2
    records = json_lines(out)
    assert [r['line'] for r in records] == [2, 4]
    assert all(set(r) == FORWARD_KEYS | {'line'} for r in records)
    assert all(r['converged'] for r in records)
    assert records[0]['pressures_pa'] == pytest.approx([150e3, -50e3, -50e3])
    assert records[1]['pressures_pa'] == pytest.approx([100e3, 20e3, -30e3])
    assert_one_line_error(err, 'line 3', "'oops'", str(path))
    # warm-started replay gives the same answer as a cold single solve
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', 100, 20, -30, '--json')
    assert code == 0
    assert records[1]['position_m'] == pytest.approx(one_json(out)['position_m'], abs=1e-9)


def test_forward_csv_all_good_rows_exit_0_and_blank_lines(capsys, tmp_path):
    path = write(tmp_path, 'p.csv', 'a,b,c\n0,0,0\n\n10,0,0\n')
    code, out, err = run(capsys, 'forward', '--pressures-csv', path, '--json')
    assert code == 0 and err == ''
    assert [r['line'] for r in json_lines(out)] == [2, 4]


@pytest.mark.parametrize('body, fragments', [
    ('a,b,c\n1,2\n0,0,0\n', ['line 2', 'expected 3 pressures']),
    ('a,b,c\n0,0,0\n0,0,151\n', ['line 3', 'pressure 3 = 151 kPa', 'outside the limits']),
    ('a,b,c\n0,0,0\n0,inf,0\n', ['line 3', 'finite']),
])
def test_forward_csv_bad_rows(capsys, tmp_path, body, fragments):
    path = write(tmp_path, 'p.csv', body)
    code, out, err = run(capsys, 'forward', '--pressures-csv', path, '--json')
    assert code == 2
    assert len(json_lines(out)) == 1
    assert_one_line_error(err, *fragments)


def test_subprocess_forward_csv_replay_streams_json_lines(tmp_path):
    path = write(tmp_path, 'p.csv', 'p1,p2,p3\n150,-50,-50\n1,2,x,4\n0,0,0\n')
    proc = run_subprocess('forward', '--pressures-csv', path, '--json')
    assert proc.returncode == 2, proc.stderr
    records = json_lines(proc.stdout)
    assert [r['line'] for r in records] == [2, 4]
    assert records[1]['position_m'][0] == pytest.approx(0.0, abs=1e-9)
    assert_one_line_error(proc.stderr, 'line 3')


def test_subprocess_forward_single_and_bad_input():
    proc = run_subprocess('forward', '--pressures-kpa', 150, -50, -50, '--json')
    assert proc.returncode == 0, proc.stderr
    d = one_json(proc.stdout)
    assert d['position_m'][0] < -0.01 and d['converged'] is True
    proc = run_subprocess('forward', '--pressures-kpa', 150, -50)
    assert proc.returncode == 2 and proc.stdout == ''
    assert_one_line_error(proc.stderr, 'expected 3 pressures')


def test_subprocess_reads_csv_from_stdin():
    proc = run_subprocess('forward', '--pressures-csv', '-', '--json', stdin='a,b,c\n0,0,0\n')
    assert proc.returncode == 0, proc.stderr
    assert json_lines(proc.stdout)[0]['line'] == 2


# ----------------------------------------------------------------- inverse
def test_inverse_round_trip_one_segment(capsys):
    pressures_kpa = (120.0, 20.0, -30.0)
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', *pressures_kpa, '--json')
    assert code == 0
    position = one_json(out)['position_m']
    code, out, err = run(capsys, 'inverse', '--position', *nums(position), '--json')
    assert code == 0, err
    d = one_json(out)
    assert set(d) == INVERSE_KEYS
    assert d['reachable'] is True and d['success'] is True and d['converged'] is True
    assert d['position_error_m'] < 1e-6
    assert d['angle_error_rad'] is None and d['target_z_axis'] is None
    assert np.allclose(np.array(d['pressures_pa']) / 1e3, pressures_kpa, atol=1e-3)
    assert d['active_limits'] == [0, 0, 0]
    assert d['target_position_m'] == pytest.approx(position, abs=1e-15)
    assert d['position_m'] == pytest.approx(position, abs=1e-6)


def test_inverse_human_summary(capsys, one):
    fw = solve_forward(one, [60e3, 0.0, 10e3])
    code, out, err = run(capsys, 'inverse', '--position', *nums(fw.position))
    assert code == 0, err
    assert 'reachable      yes' in out
    assert 'position error' in out and 'mm' in out and 'active limits  none' in out
    assert 'kPa' in out and 'target' in out


def test_inverse_one_segment_z_axis_is_ignored_with_warning(capsys, one):
    fw = solve_forward(one, [60e3, 0.0, 10e3])
    code, out, err = run(capsys, 'inverse', '--position', *nums(fw.position),
                         '--z-axis', 0, 0, 1, '--json')
    assert code == 0
    assert 'warning' in err and 'ignored' in err
    assert one_json(out)['target_z_axis'] is None


def test_inverse_two_segment_with_z_axis(capsys, two):
    pressures = np.array([40.0, 0.0, -20.0, 30.0, 0.0, 10.0]) * 1e3
    fw = solve_forward(two, pressures)
    assert fw.success
    code, out, err = run(capsys, 'inverse', '--config', 'two_segment',
                         '--position', *nums(fw.position),
                         '--z-axis', *nums(fw.z_axis), '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['reachable'] is True and d['success'] is True
    assert d['position_error_m'] < 1e-6 and d['angle_error_rad'] < 1e-6
    p = np.array(d['pressures_pa'])
    assert p.shape == (6,) and np.all((p >= TWO_SEG_LIMITS_PA[0]) & (p <= TWO_SEG_LIMITS_PA[1]))
    assert d['target_z_axis'] == pytest.approx(list(fw.z_axis), abs=1e-12)
    # the returned pressures really produce the pose
    check = solve_forward(two, p)
    assert np.linalg.norm(check.position - fw.position) < 1e-6
    assert np.linalg.norm(check.z_axis - fw.z_axis) < 1e-6


def test_inverse_unreachable_target(capsys):
    # 3 cm above the tip of the fully extended robot (about 107.5 mm at 150 kPa)
    code, out, err = run(capsys, 'inverse', '--position', 0, 0, 0.14, '--json')
    assert code == 1, err            # a result asked for, not reached: 1, the result printed
    d = one_json(out)
    assert d['reachable'] is False and d['success'] is False
    p = np.array(d['pressures_pa'])
    assert np.all(np.isfinite(p))
    assert np.all((p >= ONE_SEG_LIMITS_PA[0]) & (p <= ONE_SEG_LIMITS_PA[1]))
    assert any(a != 0 for a in d['active_limits'])
    assert d['position_error_m'] > 0.02
    assert 'unreachable' in d['message']


def test_unreachable_is_exit_1_for_inverse_its_batch_and_track(capsys, tmp_path, one):
    """One rule: a target not reached is exit status 1, the answers still printed."""
    code, out, _ = run(capsys, 'inverse', '--position', 0, 0, 0.14)
    assert code == 1 and re.search(r'reachable\s+no', out), out
    reached = solve_forward(one, np.array([100e3, 0, 0])).position
    path = write(tmp_path, 't.csv', f'x,y,z\n{",".join(map(repr, map(float, reached)))}\n'
                                    '0,0,0.14\n')
    code, out, err = run(capsys, 'inverse', '--targets-csv', path, '--json')
    assert code == 1 and err == ''
    assert [r['reachable'] for r in json_lines(out)] == [True, False]
    code, out, _ = run(capsys, 'inverse', '--targets-csv', write(tmp_path, 'ok.csv', (
        f'x,y,z\n{",".join(map(repr, map(float, reached)))}\n')), '--json')
    assert code == 0 and json_lines(out)[0]['reachable'] is True
    code, _, _ = run(capsys, 'track', '--trajectory', 'planar_circle', '--radius-mm', '60',
                     '--points', '2', '--quiet')
    assert code == 1
    # the contract is in --help
    assert cli.main(['--help']) == 0
    assert '1 a result asked for was not reached' in ' '.join(capsys.readouterr().out.split())


def test_forward_batch_row_not_converged_is_exit_1(capsys, tmp_path, monkeypatch):
    real = cli_solve.solve_forward

    def second_fails(model, pressures, **kwargs):
        fw = real(model, pressures, **kwargs)
        if pressures[0] == 20e3:
            fw.converged, fw.status, fw.message = False, 3, 'did not converge (test)'
        return fw

    monkeypatch.setattr(cli_solve, 'solve_forward', second_fails)
    path = write(tmp_path, 'p.csv', 'a,b,c\n10,0,0\n20,0,0\n30,0,0\n')
    code, out, err = run(capsys, 'forward', '--pressures-csv', path, '--json')
    assert code == 1 and err == ''
    assert [r['converged'] for r in json_lines(out)] == [True, False, True]


def test_inverse_targets_csv_one_segment(capsys, tmp_path, one):
    targets = [solve_forward(one, np.array(p) * 1e3).position
               for p in [(100, 0, 0), (110, 0, 0)]]
    path = write(tmp_path, 't.csv', f'z,y,x\n{_zyx(targets[0])}\n1,2\n{_zyx(targets[1])}\n')
    code, out, err = run(capsys, 'inverse', '--targets-csv', path, '--json')
    assert code == 2
    records = json_lines(out)
    assert [r['line'] for r in records] == [2, 4]
    for r, t in zip(records, targets):
        assert set(r) == INVERSE_KEYS | {'line'}
        assert r['reachable'] is True and r['position_error_m'] < 1e-6
        assert r['target_position_m'] == pytest.approx(list(t), abs=1e-15)
    assert np.allclose(np.array(records[1]['pressures_pa']) / 1e3, [110, 0, 0], atol=1e-3)
    assert_one_line_error(err, 'line 3', 'expected 3 fields')


def _zyx(t):
    """A target row in the column order z, y, x (the header names the columns)."""
    return ','.join(repr(float(v)) for v in (t[2], t[1], t[0]))


def test_inverse_targets_csv_two_segment(capsys, tmp_path, two):
    fws = [solve_forward(two, np.array(p) * 1e3)
           for p in [(40, 0, -20, 30, 0, 10), (45, 0, -20, 30, 0, 10)]]
    body = 'x,y,z,zx,zy,zz\n' + ''.join(
        ','.join(repr(float(v)) for v in (*f.position, *f.z_axis)) + '\n' for f in fws)
    path = write(tmp_path, 't.csv', body)
    code, out, err = run(capsys, 'inverse', '--config', 'two_segment', '--targets-csv', path,
                         '--json')
    assert code == 0, err
    records = json_lines(out)
    assert len(records) == 2
    for r in records:
        assert r['reachable'] is True
        assert r['position_error_m'] < 1e-6 and r['angle_error_rad'] < 1e-6


# --------------------------------------------------------------- bad input
BAD_INPUT = [
    (['forward', '--pressures-kpa', '150', '-50'], ['expected 3 pressures', 'got 2']),
    (['forward', '--config', 'two_segment', '--pressures-kpa', '1', '2', '3'],
     ['expected 6 pressures', 'got 3']),
    (['forward', '--config', 'no_such_robot', '--pressures-kpa', '0', '0', '0'],
     ['no_such_robot', 'unknown robot name']),
    (['forward', '--config', '/nonexistent/robot.yaml', '--pressures-kpa', '0', '0', '0'],
     ['/nonexistent/robot.yaml', 'no such robot file']),
    (['forward', '--pressures-kpa', '1', 'abc', '3'], ['--pressures-kpa', "'abc'"]),
    (['forward', '--pressures-kpa', '1', 'nan', '3'], ['--pressures-kpa', 'finite']),
    (['forward', '--pressures-kpa', '151', '0', '0'],
     ['pressure 1 = 151 kPa', 'outside the limits']),
    (['forward', '--pressures-kpa', '0', '-60', '0'],
     ['pressure 2 = -60 kPa', 'outside the limits']),
    (['forward', '--config', 'two_segment', '--pressures-kpa', '0', '0', '0', '0', '0', '121'],
     ['pressure 6 = 121 kPa', '[-50, 120] kPa']),
    (['forward', '--pressures-kpa', '0', '0', '0', '--payload-kg', '-0.1'], ['--payload-kg']),
    (['forward', '--pressures-kpa', '0', '0', '0', '--payload-kg', 'heavy'],
     ['--payload-kg', "'heavy'"]),
    (['forward', '--pressures-kpa', '0', '0', '0', '--elements', '0'], ['--elements']),
    (['forward', '--pressures-kpa', '0', '0', '0', '--elements', '2.5'], ['--elements', "'2.5'"]),
    (['forward', '--pressures-csv', '/nonexistent/p.csv', '--json'],
     ['/nonexistent/p.csv', 'cannot open']),
    (['forward'], ['--pressures-kpa', '--pressures-csv']),
    ([], ['COMMAND']),
    (['fly'], ["'fly'"]),
    (['inverse', '--config', 'two_segment', '--position', '0', '0', '0.2'], ['z-axis']),
    (['inverse', '--config', 'two_segment', '--position', '0', '0', '0.2',
      '--z-axis', '0', '0', '0'], ['z-axis']),
    (['inverse', '--position', '0', 'zero', '0.1'], ['--position', "'zero'"]),
    (['inverse', '--position', '0', '0'], ['--position', 'expected 3']),
    (['inverse', '--targets-csv', '/nonexistent/t.csv', '--json'],
     ['/nonexistent/t.csv', 'cannot open']),
]


@pytest.mark.parametrize('argv, fragments', BAD_INPUT,
                         ids=[' '.join(a) or '(none)' for a, _ in BAD_INPUT])
def test_bad_input_exits_2_with_one_line(capsys, argv, fragments):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ''
    assert_one_line_error(err, *fragments)


@pytest.mark.parametrize('command, option, body, fragments', [
    ('forward', '--pressures-csv', '', ['no header']),
    ('forward', '--pressures-csv', '1,2,3\n0,0,0\n', ['line 1', 'header']),
    ('forward', '--pressures-csv', 'a,b\n0,0\n', ['line 1', 'expected 3']),
    ('inverse', '--targets-csv', 'x,y,depth\n0,0,0.1\n',
     ['line 1', "'depth'", 'missing column(s) z']),
    ('inverse', '--targets-csv', 'x,y,z,x\n0,0,0.1,0\n', ['line 1', 'duplicated']),
])
def test_bad_csv_header_exits_2(capsys, tmp_path, command, option, body, fragments):
    path = write(tmp_path, 'bad.csv', body)
    code, out, err = run(capsys, command, option, path, '--json')
    assert code == 2 and out == ''
    assert_one_line_error(err, *fragments)


def test_two_segment_targets_csv_needs_z_axis_columns(capsys, tmp_path):
    path = write(tmp_path, 't.csv', 'x,y,z\n0,0,0.2\n')
    code, out, err = run(capsys, 'inverse', '--config', 'two_segment', '--targets-csv', path,
                         '--json')
    assert code == 2 and out == ''
    assert_one_line_error(err, 'zx, zy, zz')


def test_batch_requires_json(capsys, tmp_path):
    path = write(tmp_path, 'p.csv', 'a,b,c\n0,0,0\n')
    code, out, err = run(capsys, 'forward', '--pressures-csv', path)
    assert code == 2 and out == ''
    assert_one_line_error(err, '--json')


def test_bad_robot_file_exits_2_with_one_line(capsys, tmp_path):
    text = (REPO / 'config' / 'one_segment.yaml').read_text()
    text = text.replace('p_max_kpa: 150.0', 'p_max_kpa: oops')
    path = write(tmp_path, 'robot.yaml', text)
    code, out, err = run(capsys, 'forward', '--config', path, '--pressures-kpa', 0, 0, 0)
    assert code == 2 and out == ''
    assert_one_line_error(err, 'p_max_kpa')


# ----------------------------------------------------------------- misc
def test_help_exits_0(capsys):
    assert cli.main(['--help']) == 0
    out = capsys.readouterr().out
    assert 'forward' in out and 'inverse' in out
    assert cli.main(['forward', '--help']) == 0
    out = capsys.readouterr().out
    assert '--pressures-kpa' in out and '--pressures-csv' in out


def test_json_safe_maps_non_finite_to_null():
    record = {'a': float('nan'), 'b': [1.0, float('inf'), np.float64(-np.inf)], 'c': np.arange(2),
              'd': np.bool_(True), 'e': (np.int64(3), None, 'text')}
    safe = cli.json_safe(record)
    assert json.loads(json.dumps(safe, allow_nan=False)) == {
        'a': None, 'b': [1.0, None, None], 'c': [0, 1], 'd': True, 'e': [3, None, 'text']}


def test_command_family_hook_dispatches_extra_subcommand(capsys, monkeypatch):
    def register(subparsers):
        p = subparsers.add_parser('hello', help='test subcommand')
        p.add_argument('--times', type=int, default=1)
        p.set_defaults(func=lambda args: print('hello ' * args.times) or 7)

    fake = types.ModuleType('bellow_ancf_ros.cli.hello')
    fake.register = register
    monkeypatch.setitem(sys.modules, 'bellow_ancf_ros.cli.hello', fake)
    monkeypatch.setattr(cli, 'COMMAND_FAMILIES', cli.COMMAND_FAMILIES + ('hello',))
    code, out, _ = run(capsys, 'hello', '--times', 2)
    assert code == 7 and out.strip() == 'hello hello'
    code, _, err = run(capsys, 'hello', '--times', 'x')
    assert code == 2
    assert_one_line_error(err, '--times')


def test_help_lists_every_family_in_order(capsys):
    code, out, _ = run(capsys, '--help')
    assert code == 0
    commands = ['forward', 'inverse', 'compliance', 'stiffness', 'modes', 'simulate',
                'identify', 'convergence',
                'workspace', 'compare-pcc',
                'track', 'calibrate', 'record', 'warm-up']
    listed = [m.group(1) for m in re.finditer(r'^    (\S+)', out, re.MULTILINE)]
    assert listed == commands


def _modules_after_importing(*packages) -> set:
    """The modules a fresh interpreter holds after importing ``packages``."""
    code = f'import sys, {", ".join(packages)}; print(" ".join(sys.modules))'
    proc = subprocess.run([sys.executable, '-c', code], cwd=REPO, env=subprocess_env(),
                          timeout=120, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return set(proc.stdout.split())


def test_cli_does_not_import_rclpy():
    loaded = _modules_after_importing('bellow_ancf_ros.cli')
    assert not any(m == 'rclpy' or m.startswith('rclpy.') for m in loaded)


def test_nothing_loads_scipy_stats_until_a_fit_needs_its_t_quantiles():
    """``scipy.stats`` takes 0.9 s to import: a node process or a solve never pays it."""
    assert 'scipy.stats' not in _modules_after_importing('bellow_ancf_ros.core',
                                                         'bellow_ancf_ros.cli')


# ----------------------------------------------------------------- demo
def test_demo_runs(capsys):
    code = demo.main()
    out = capsys.readouterr().out
    assert code == 0, out
    assert 'one-segment robot' in out and 'two-segment robot' in out
    assert 'forward' in out and 'inverse' in out and 'FAILED' not in out
    assert 'unreachable' in out
    assert 'ms' in out and 'demo finished' in out
    seconds = float(out.rsplit('demo finished in ', 1)[1].split(' s')[0])
    assert math.isfinite(seconds) and seconds < 60


# ------------------------------------------- negative numbers, closed pipes
@pytest.mark.parametrize('text', ['-1e1', '-10', '-10.0', '-1E+1', '-.1e2', '-1_0'])
def test_negative_pressures_parse_in_any_notation(capsys, text):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', text, '0', '0', '--json')
    assert code == 0, err
    assert one_json(out)['pressures_pa'] == pytest.approx([-10e3, 0.0, 0.0])


def test_negative_target_and_axis_components_parse(capsys, two):
    code, out, err = run(capsys, 'inverse', '--position', '-1e-3', '0', '0.095', '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['reachable'] and d['target_position_m'] == [-1e-3, 0.0, 0.095]
    fw = solve_forward(two, [100e3, 0.0, 0.0, 60e3, 0.0, 0.0])  # bends towards -x
    z = fw.z_axis * 100  # any length is a direction
    code, out, err = run(capsys, 'inverse', '--config', 'two_segment',
                         '--position', *nums(fw.position),
                         '--z-axis', *[f'{v:.17e}' for v in z], '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['reachable'] and d['target_z_axis'][0] < 0 and d['position_error_m'] < 1e-6


def test_negative_infinity_is_reported_as_not_finite(capsys):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', '-inf', '0', '0')
    assert code == 2 and out == ''
    assert_one_line_error(err, '--pressures-kpa', "not a finite number: '-inf'")


def test_closed_pipe_ends_quietly(tmp_path):
    rows = '\n'.join(f'{3 * k},0,-10' for k in range(40))
    path = write(tmp_path, 'rows.csv', 'p1,p2,p3\n' + rows + '\n')
    command = (f'"{sys.executable}" -m bellow_ancf_ros.cli forward '
               f'--pressures-csv "{path}" --json | head -1')
    proc = subprocess.run(command, shell=True, cwd=REPO, env=subprocess_env(), capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0
    assert len(json_lines(proc.stdout)) == 1
    assert proc.stderr == ''


def test_element_count_that_cannot_carry_the_plates_is_refused(capsys):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', '0', '0', '0', '--elements', '2')
    assert code == 2 and out == ''
    assert_one_line_error(err, '--elements', 'model.n_elements', 'smallest count that works is 3')
    code, out, err = run(capsys, 'forward', '--pressures-kpa', '0', '0', '0', '--elements', '3',
                         '--json')
    assert code == 0, err


def test_tip_force_in_forward_and_inverse_single_and_batch(capsys, one, tmp_path):
    """``--tip-force-n``: the core's answers under the force, single solves and CSV batches."""
    F = [0.05, -0.02, 0.01]
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', 30, 0, 10, '--tip-force-n', *F,
                       '--json')
    d = one_json(out)
    assert code == 0 and d['tip_force_n'] == F
    ref = solve_forward(one, [30e3, 0.0, 10e3], tip_force_n=F)
    assert d['position_m'] == pytest.approx(ref.position.tolist(), abs=1e-12)
    code, out, _ = run(capsys, 'forward', '--pressures-kpa', 30, 0, 10, '--tip-force-n', *F)
    assert code == 0 and re.search(r'tip force\s+0\.05 -0\.02 0\.01\s+N', out), out
    # inverse: the target is reached under the force; the batch gives the same answers
    code, out, err = run(capsys, 'inverse', '--position', *nums(ref.position), '--tip-force-n',
                         *F, '--json')
    d = one_json(out)
    assert code == 0 and d['success'] and d['tip_force_n'] == F, err
    assert np.allclose(np.array(d['pressures_pa']), [30e3, 0.0, 10e3], atol=1e-3)
    csv_path = tmp_path / 'targets.csv'
    csv_path.write_text('x,y,z\n' + ','.join(nums(ref.position)) + '\n')
    code, out, _ = run(capsys, 'inverse', '--targets-csv', str(csv_path), '--tip-force-n', *F,
                       '--json')
    batch = one_json(out)['pressures_pa']
    assert code == 0 and batch == pytest.approx(d['pressures_pa'], abs=1e-6)
    pcsv = tmp_path / 'p.csv'
    pcsv.write_text('a1,a2,a3\n30,0,10\n')
    code, out, _ = run(capsys, 'forward', '--pressures-csv', str(pcsv), '--tip-force-n', *F,
                       '--json')
    batch = one_json(out)['position_m']
    assert code == 0 and batch == pytest.approx(ref.position.tolist(), abs=1e-12)


@pytest.mark.parametrize('force, says', [(['nan', '0', '0'], 'not a finite number'),
                                         (['5000', '0', '0'], 'refused as absurd')])
def test_bad_tip_force_is_one_line_and_exit_2(capsys, force, says):
    code, out, err = run(capsys, 'forward', '--pressures-kpa', 0, 0, 0, '--tip-force-n', *force)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err
