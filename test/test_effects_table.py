"""bench/effects_bench.py: its tables in the docs are its run file's, rendered by one renderer."""

import copy
import json
import os
import sys

import pytest

from bellow_ancf_ros.core.sim import EFFECTS, PlantEffects

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))
import effects_bench  # noqa: E402


def _row(robot, speed, label, rmse, two, step=None, after=()):
    r = {'robot': robot, 'speed': speed, 'row': label, 'frame': 'azimuthal', 'feedback': True,
         'effects': {}, 'rmse_mm': rmse, 'max_mm': 2 * rmse, 'step_after_outlier_kpa': step,
         'step_p99_kpa': 0.5, 'after_dropout_mm': list(after), 'out_of_limits': 0,
         'wall_s': 1.0}
    if two:
        r.update(rmse_deg=0.02, max_deg=0.05)
    return r


def _data(rows, speeds=(4.0,)):
    return {'format': 1, 'date': '2026-12-04T05:30:12+00:00', 'wall_s': 187.6, 'seed': 1,
            'machine': {'cpus': 2, 'jobs': 1, 'load_start': [0.5, 0.1, 0.0],
                        'load_end': [1.96, 1.0, 0.4]},
            'options': {'speeds': list(speeds), 'robots': ['one_segment', 'two_segment'],
                        'paper_period_s': 20.0, 'control_hz': 50.0},
            'rows': rows}


def _synthetic():
    return _data([
        _row('one_segment', 4.0, 'ideal robot', 0.05, False),
        _row('one_segment', 4.0, 'bellows creep', 0.04999, False),   # rounds to -0.000
        _row('one_segment', 4.0, 'mocap outliers', 0.06, False, step=1.454),
        _row('one_segment', 4.0, 'mocap dropouts', 0.048, False, after=(0.0431, 0.02)),
        _row('two_segment', 4.0, 'ideal robot', 0.047, True),
        _row('two_segment', 4.0, 'regulator hysteresis', 0.117, True)])


def test_render_gives_each_robot_and_speed_a_table_with_costs_against_the_ideal_row():
    text = effects_bench.render(_synthetic())
    lines = text.splitlines()
    assert lines[0] == ('closed loop against the mismatched simulated robot, one effect at a '
                        'time (seed 1; true errors over the second period; 188 s)')
    assert 'one_segment, 4x the paper speed (5 s period):' in lines
    assert 'two_segment, 4x the paper speed (5 s period):' in lines
    row = {ln.split('  ')[1].strip(): ln for ln in lines if ln.startswith('  ') and
           not ln.startswith('  row')}
    assert row['bellows creep'].split()[2:5] == ['0.050', '0.100', '+0.000']   # no -0.000
    assert '-0.000' not in text
    assert row['mocap outliers'].split()[2:6] == ['0.060', '0.120', '+0.010', '1.45']
    assert row['mocap dropouts'].endswith('  0.043, 0.020')
    assert row['bellows creep'].endswith('  -')
    # the two-segment table has the angle columns, the one-segment one does not
    heads = [ln for ln in lines if ln.startswith('  row')]
    assert ['RMSE deg' in h for h in heads] == [False, True]
    hysteresis = row['regulator hysteresis'].split()[2:7]
    assert hysteresis == ['0.117', '0.234', '+0.070', '0.020', '0.050']
    assert lines[-1] == 'commands out of limits or not finite: 0'


def test_render_is_deterministic_and_counts_every_command_out_of_limits():
    data = _synthetic()
    assert effects_bench.render(data) == effects_bench.render(copy.deepcopy(data))
    data['rows'][2]['out_of_limits'] = 3
    data['rows'][5]['out_of_limits'] = 1
    assert effects_bench.render(data).splitlines()[-1] == (
        'commands out of limits or not finite: 4')


def test_markdown_is_the_printed_tables_in_a_fence_with_the_run_s_date_and_machine():
    data = _synthetic()
    md = effects_bench.markdown(data)
    head, rest = md.split('\n\n', 1)
    assert head == ('Output of one run (2026-12-04 05:30 UTC, 188 s on 1 worker, 2 CPUs, load '
                    'average (1 min) 0.50 at the start and 1.96 at the end; the run writes '
                    '`bench/effects.json`):')
    assert rest == '```\n' + effects_bench.render(data) + '```\n'


def test_render_option_prints_a_run_file_without_running(tmp_path, capsys):
    path = tmp_path / 'effects.json'
    data = _synthetic()
    path.write_text(json.dumps(data))
    assert effects_bench.main(['--render', '--out', str(path)]) == 0
    assert capsys.readouterr().out == effects_bench.render(data)
    data['rows'][0]['out_of_limits'] = 2   # an unsafe run is a failure, read back too
    path.write_text(json.dumps(data))
    assert effects_bench.main(['--render', '--out', str(path)]) == 1


def test_bad_run_files_and_a_partial_run_for_the_document_are_refused(tmp_path, capsys):
    missing = tmp_path / 'missing.json'
    assert effects_bench.main(['--render', '--out', str(missing)]) == 2
    assert 'cannot read the run file' in capsys.readouterr().err
    bad = tmp_path / 'bad.json'
    bad.write_text('{}')
    assert effects_bench.main(['--render', '--out', str(bad)]) == 2
    assert 'cannot read the run file' in capsys.readouterr().err
    quick = tmp_path / 'quick.json'
    quick.write_text(json.dumps(_synthetic()))   # 4x only
    assert effects_bench.main(['--render', '--doc', '--out', str(quick)]) == 2
    assert 'is not a full run' in capsys.readouterr().err
    assert effects_bench.main(['--quick', '--doc']) == 2
    assert '--doc: not with --quick' in capsys.readouterr().err


def test_one_real_row_goes_into_the_run_file():
    """A short row (4x, one segment, dropouts): its figures are plain JSON and render."""
    label = 'mocap dropouts'
    job = ('one_segment', 4.0, label, PlantEffects().only(label), 'azimuthal', True)
    key, out = effects_bench.run_one(job)
    assert key == job[:3]
    assert out['out_of_limits'] == 0 and out['step_after_outlier_kpa'] is None
    assert out['after_dropout_mm'] and all(0 < x < 1 for x in out['after_dropout_mm'])
    moment = {'date': '2026-12-04T05:30:12+00:00', 'load': None}
    data = effects_bench.record([job], {key: out}, jobs_n=1, start=moment, end=moment,
                                wall_s=3.0)
    data = json.loads(json.dumps(data))
    assert data['rows'][0]['effects']['dropout_every_s'] == PlantEffects().dropout_every_s
    assert data['options']['speeds'] == [4.0] and data['options']['robots'] == ['one_segment']
    with pytest.raises(KeyError):   # no ideal row: no cost to give
        effects_bench.render(data)
    data['rows'].insert(0, dict(data['rows'][0], row='ideal robot'))
    line = effects_bench.render(data).splitlines()[-3]
    assert line.startswith(f'  {label:30s}') and '+0.000' in line
    assert line.endswith('  ' + ', '.join(f'{x:.3f}' for x in out['after_dropout_mm']))


def test_the_docs_show_the_tables_of_the_committed_run():
    """docs/closed_loop.md's effects tables are bench/effects.json's, not typed by hand."""
    with open(os.path.join(ROOT, "bench", "effects.json")) as f:
        data = json.load(f)
    # a full run of today's rows: both robots, both speeds, every effect
    assert data['options']['robots'] == list(effects_bench.ROBOTS)
    assert data['options']['speeds'] == list(effects_bench.SPEEDS)
    assert set(EFFECTS) < set(effects_bench.labels())
    assert [(r['robot'], r['speed'], r['row']) for r in data['rows']] == [
        (robot, speed, label) for robot in effects_bench.ROBOTS
        for speed in effects_bench.SPEEDS for label in effects_bench.labels()]
    assert effects_bench.doc_block() == effects_bench.markdown(data)
