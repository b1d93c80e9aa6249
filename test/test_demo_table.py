"""bench/demo_table.py: make demo's table in the docs is the results file's, one run or several."""

import json
import os
import sys

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))
import demo_table  # noqa: E402
from bellow_ancf_ros.demos.closed_loop import columns  # noqa: E402
from demo_results import results  # noqa: E402


def _row(table, case):
    """The cells of the table row of ``case``."""
    line = next(ln for ln in table.splitlines() if ln.startswith(f'| {case} |'))
    return [c.strip() for c in line.strip('|').split('|')]


def _runs(*kwargs):
    out = []
    for k, kw in enumerate(kwargs, start=1):
        data = json.loads(json.dumps(results(**kw)))
        data['file'] = f'demo_results_{k}.json'
        out.append(data)
    return out


def test_one_run_gives_its_figures_goals_and_misses():
    table = demo_table.markdown(_runs({'cl_10x_mm': 0.7}))
    assert table.startswith('One run of `make demo`')
    assert 'load average (1 min) 0.12 at the start and 1.90 at the end' in table
    assert 'spread over runs is not measured by this table' in table
    assert _row(table, 'one segment, 1x (20 s)') == [
        'one segment, 1x (20 s)', '5.000 mm', '5.000 mm', '0.080 mm (0.08)', '0.050 mm',
        '0.5 mm', '0.3 mm', 'met']
    assert _row(table, 'one segment, 10x (2 s)')[-1] == '**MISSED**: RMSE 0.700 > 0.500 mm'
    row = _row(table, 'two segments, 50 g, 10x (2 s)')
    assert row[1:3] == ['', '']   # the 50 g case runs the closed loop alone
    assert row[4] == '0.610 mm / 0.183 deg'
    assert row[5:7] == ['1.5 mm / 0.75 deg', '0.5 mm / 0.5 deg']
    assert row[-1] == '**MISSED**: held 0.610 > 0.500 mm'
    assert ('ZVD-shaped 0.038 mm (goal 0.1 mm); closed loop, the correction carried to the goal, '
            'overshoot 0.210 mm (goal 0.5 mm), error from 1.5 s after the step 0.120 mm (goal '
            '0.2 mm): met.') in table
    assert 'finite and within the limits: yes; every run ended with the vent: yes' in table


def test_several_runs_give_the_range_of_each_figure_and_goals_met_in_how_many():
    table = demo_table.markdown(_runs({'cl_10x_mm': 0.4, 'zvd_mm': 0.02},
                                      {'cl_10x_mm': 0.7, 'zvd_mm': 0.05}))
    assert table.startswith('2 runs of `make demo`; each figure is the range (min-max)')
    assert '`demo_results_1.json`' in table and '`demo_results_2.json`' in table
    row = _row(table, 'one segment, 10x (2 s)')
    assert row[3] == '0.400-0.700 mm (0.40-0.70)'
    assert row[-1] == 'met in 1/2: RMSE 0.700 > 0.500 mm (run 2)'
    assert _row(table, 'one segment, 1x (20 s)')[3] == '0.080 mm (0.08)'   # the same twice
    assert _row(table, 'two segments, 1x (20 s)')[-1] == 'met in 2/2'
    assert 'ZVD-shaped 0.020-0.050 mm (goal 0.1 mm); closed loop' in table
    assert '(goal 0.2 mm): met in 2/2.' in table


def test_no_file_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(demo_table, 'committed', lambda stem='demo_results': [])
    assert demo_table.main([]) == 2
    assert 'no results file' in capsys.readouterr().err
    bad = tmp_path / 'bad.json'
    bad.write_text('{}')
    assert demo_table.main([str(bad)]) == 2
    assert 'cannot read the results files' in capsys.readouterr().err


def test_the_docs_show_the_table_of_the_committed_runs():
    """docs/closed_loop.md's make demo table is bench/demo_results*.json's, not typed by hand."""
    files = demo_table.committed()
    assert files, 'no bench/demo_results*.json'
    runs = demo_table.load(files)
    for r in runs:   # full runs, not the test's shortened one: every case, every controller
        assert r['options']['period_scale'] == 1.0 and r['options']['goals_checked']
        assert [c['key'] for c in r['cases']] == [c.key for c in columns()]
        assert [list(c['runs']) for c in r['cases']] == [list(c.case.modes) for c in columns()]
    assert demo_table.doc_block() == demo_table.markdown(runs)


def _loads(file, alone, compensated, passed=True):
    """A loads results file: ``(rmse_mm, estimate under payload + push (x))`` per run."""
    def run(compensate, rmse, x):
        return {'name': 'n', 'compensate': compensate, 'safe': True, 'vent': True,
                'n_commands': 600, 'rmse_mm': rmse, 'max_mm': 4 * rmse, 'phases': {
                    'payload': {'estimate_n': [0.001, 0.0, -0.296],
                                'truth_n': [0.0, 0.0, -0.2943], 'within': True},
                    'payload + push': {'estimate_n': [x, 0.0, -0.294],
                                       'truth_n': [0.1, 0.0, -0.2943],
                                       'within': abs(x - 0.1) <= 0.03}}}
    return {'file': file, 'date': '2026-12-04T07:40:00+00:00', 'wall_s': 40.0,
            'machine': {'cpus': 2, 'load_start': [2.43, 1.0, 1.0]}, 'simulation_time': True,
            'passed': passed, 'tolerance_n': {'lateral': 0.03, 'vertical': 0.1},
            'runs': [run(False, *alone), run(True, *compensated)]}


def test_the_loads_table_gives_each_runs_figures_and_their_range():
    one = demo_table.loads_markdown([_loads('loads_results_1.json', (0.4, 0.099),
                                            (0.41, 0.1))])
    assert one.startswith('One run of the loads phase (`loads_results_1.json`: '
                          '2026-12-04 07:40 UTC, 40 s, load 2.4 at the start, simulation time, '
                          'PASS).')
    assert ('| integral feedback alone | 0.40 mm (1.60) | 0.001, 0.000, -0.296 N | '
            '0.099, 0.000, -0.294 N | 1/1 |') in one
    assert 'estimator, payload + push (truth 0.100, 0.000, -0.294 N)' in one
    two = demo_table.loads_markdown([
        _loads('a.json', (0.4, 0.099), (0.41, 0.1)),
        _loads('b.json', (0.38, 0.2), (0.39, 0.101), passed=False)])
    assert '2 runs of the loads phase' in two and 'FAIL' in two
    assert '| integral feedback alone | 0.38-0.40 mm (1.52-1.60) | ' in two
    assert '0.099-0.200, 0.000, -0.294 N | 1/2 |' in two


def test_the_docs_show_the_loads_table_of_the_committed_runs():
    """docs/closed_loop.md's loads table is bench/loads_results*.json's, not typed by hand."""
    files = demo_table.committed('loads_results')
    assert files, 'no bench/loads_results*.json'
    assert (demo_table.doc_block(demo_table.LOADS_START, demo_table.LOADS_END)
            == demo_table.loads_markdown(demo_table.load(files)))
