"""docs/performance.md's measured tables are the runs' output files, rendered, not typed."""

import json
import os
import sys

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))
import dynamics_bench  # noqa: E402
import redundant_bench  # noqa: E402
import stream_latency  # noqa: E402


def _machine():
    return {'cpus': 2, 'load_start': [0.5, 0.4, 0.3], 'load_end': [1.25, 0.9, 0.6]}


def _redundant():
    """A synthetic run file: one robot meets the targets, one misses (a slow solve)."""
    return {'date': '2026-01-02T03:04:05+00:00', 'wall_s': 12.4, 'seed': 7,
            'limits': {'worst_s': 5.0, 'median_s': 1.0}, 'machine': _machine(),
            'rows': [{'m': 1, 'robot': 'one_segment', 'n': 3, 'ok_cold': 3, 'ok_walk': 3,
                      'cold': [0.001, 0.003, 0.002], 'walk': [0.004, 0.0, 0.006],
                      'dp': 0.0104},
                     {'m': 3, 'robot': 'three_segment', 'n': 3, 'ok_cold': 2, 'ok_walk': 3,
                      'cold': [0.2, 0.3, 6.0], 'walk': [0.1, 0.2, 0.3], 'dp': 0.000333}]}


def test_redundant_table_gives_each_robots_figures_and_verdict():
    text = redundant_bench.markdown(_redundant())
    lines = text.splitlines()
    assert lines[0].startswith('One run (2026-01-02 03:04 UTC, 12 s, seed 7, 2 CPUs, load '
                               'average (1 min) 0.50 at the start and 1.25 at the end;')
    assert 'each solve under 5 s, the medians under 1 s' in lines[0]
    assert lines[2] == ('| segments | robot | reached cold | cold median | p99 | worst | '
                        'reached walk | walk median | worst | max \\|dP\\| cold vs walk | '
                        'targets |')
    assert [c.strip() for c in lines[4].split('|')[1:-1]] == [
        '1', 'one_segment', '3 of 3', '0.002 s', '0.003 s', '0.003 s', '3 of 3', '0.004 s',
        '0.006 s', '0.0104 Pa', 'met']
    p99 = format(0.3 + 0.98 * (6.0 - 0.3), '.3f')   # numpy's linear percentile of 3 values
    assert [c.strip() for c in lines[5].split('|')[1:-1]] == [
        '3', 'three_segment', '2 of 3', '0.300 s', f'{p99} s', '6.000 s', '3 of 3', '0.200 s',
        '0.300 s', '0.000333 Pa', '**MISSED**']
    assert len(lines) == 6 and text.endswith('\n')


def test_redundant_row_misses_on_an_unreached_target_or_a_slow_median():
    limits = {'worst_s': 5.0, 'median_s': 1.0}
    row = dict(_redundant()['rows'][0])
    assert redundant_bench.good(row, limits)
    assert not redundant_bench.good(dict(row, ok_walk=2), limits)
    assert not redundant_bench.good(dict(row, walk=[1.5, 1.5, 0.1]), limits)


def test_the_docs_show_the_redundant_table_of_the_last_run():
    with open(os.path.join(ROOT, 'bench', 'redundant.json')) as f:
        data = json.load(f)
    assert [r['m'] for r in data['rows']] == [1, 2, 3, 4]
    assert redundant_bench.doc_block() == redundant_bench.markdown(data)


def _stream():
    """A synthetic run file: one robot within the ratio, one beyond it."""
    run = {'robot': 'one_segment', 'rate_hz': 100.0, 'sent': 1900, 'answered': 1900,
           'unanswered_fraction': 0.0, 'median_s': 0.00198, 'p99_s': 0.0031,
           'single_median_s': 0.0025, 'ratio': 0.792}
    return {'date': '2026-01-02T03:04:05+00:00', 'wall_s': 61.6, 'seconds': 20.0,
            'rate_hz': 100.0, 'ratio_limit': 1.5, 'machine': _machine(),
            'runs': [run, dict(run, robot='two_segment', answered=1875,
                               unanswered_fraction=25 / 1900, median_s=0.00744,
                               p99_s=0.01292, single_median_s=0.00368, ratio=2.02)]}


def test_stream_latency_table_gives_each_robots_figures_and_verdict():
    text = stream_latency.markdown(_stream())
    lines = text.splitlines()
    assert lines[0] == ('One run (2026-01-02 03:04 UTC, 62 s, 20 s streams at 100 Hz, 2 CPUs, '
                        'load average (1 min) 0.50 at the start and 1.25 at the end; the run '
                        'writes `bench/stream_latency.json`); target: the median within 1.5x '
                        'of one target at a time.')
    assert lines[2] == ('| robot | median | p99 | unanswered | one at a time (median) | '
                        'median / one at a time | target |')
    assert [c.strip() for c in lines[4].split('|')[1:-1]] == [
        'one_segment', '1.98 ms', '3.10 ms', '0.00 % of 1900', '2.50 ms', '0.79', 'met']
    assert [c.strip() for c in lines[5].split('|')[1:-1]] == [
        'two_segment', '7.44 ms', '12.92 ms', '1.32 % of 1900', '3.68 ms', '2.02',
        '**MISSED**']
    assert len(lines) == 6 and text.endswith('\n')


def test_the_docs_show_the_stream_latency_table_of_the_last_run():
    with open(os.path.join(ROOT, 'bench', 'stream_latency.json')) as f:
        data = json.load(f)
    assert [r['robot'] for r in data['runs']] == list(stream_latency.ROBOTS)
    assert stream_latency.doc_block() == stream_latency.markdown(data)


def _dynamics():
    """A synthetic dynamics run file: one robot, the integrator meets its goal, simulate not."""
    def run(way, rtf):
        return {'kind': 'sine', 'way': way, 'steps': 160, 'rtf': rtf, 'halvings': 0,
                'completed': True, 'step_cpu_median_s': 1e-4, 'step_cpu_p99_s': 2e-4}
    robot = {'m': 1, 'robot': 'one_segment', 'first_mode_hz': 10.5, 'step_s': 0.00238,
             'periods': 4.0, 'force_n': 0.117, 'modes_s': [0.02, 0.03, 0.025],
             'runs': [run('integrator', [20.0, 22.0, 21.0]), run('simulate', [25.0, 29.0, 28.0])]}
    return {'date': '2026-01-02T03:04:05+00:00', 'load': [0.5, 0.4, 0.3], 'cpus': 2,
            'reps': 3, 'check_s': 0.01, 'robots': [robot]}


def test_dynamics_bench_rows_give_verdicts_and_simulates_ratio():
    lines = dynamics_bench.text(_dynamics()).splitlines()
    assert lines[0].endswith('2 CPUs, load average 0.50, 0.40, 0.30 (1, 5, 15 min); '
                             '2026-01-02 03:04 UTC')
    assert 'first mode 10.500 Hz, default step 2.380 ms' in lines[1]
    assert 'RTF median   21.00x  lowest   20.00x' in lines[2] and 'PASS (goal 10x)' in lines[2]
    assert lines[3].endswith('MISS (goal 30x)  1.33x the integrator')   # 28 / 21
    assert lines[4] == '  modes    natural_modes (6 modes) median     25.0 ms, max     30.0 ms'


def test_dynamics_bench_rows_of_the_public_api():
    """The rows of SimulatedRobot and LoopSimulation: verdicts at the goal, the robot's share."""
    data = _dynamics()
    data['robots'][0]['public'] = [
        {'what': 'SimulatedRobot', 'rtf': [9.0, 11.0, 10.0], 'robot_share': [1.0] * 3},
        {'what': 'LoopSimulation', 'rtf': [3.0, 4.0, 5.0], 'robot_share': [0.5, 0.6, 0.55]}]
    lines = dynamics_bench.text(data).splitlines()
    assert lines[4] == ('  SimulatedRobot  of one_segment_mismatched  RTF median   10.00x  lowest '
                        '   9.00x  MISS (goal 30x)')
    assert lines[5].endswith('MISS (goal 30x)  the robot 55 % of it (alone 7.27x), the '
                             'controller the rest')
    assert lines[6].startswith('  modes')


def test_the_docs_show_the_dynamics_bench_of_the_last_run():
    with open(os.path.join(ROOT, 'bench', 'dynamics.json')) as f:
        data = json.load(f)
    assert [r['m'] for r in data['robots']] == [1, 2, 3]
    assert dynamics_bench.doc_block() == dynamics_bench.text(data)
