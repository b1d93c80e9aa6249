"""The identification, study and tracking subcommands of ``bellow-ancf``.

``cli/identify.py``, ``cli/studies.py`` and ``cli/track.py``.

Each subcommand runs in-process on the shipped data or a default robot; its
numbers are checked and its plot must be a valid PNG.
"""

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from bellow_ancf_ros import cli
from bellow_ancf_ros.core import load_robot

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / 'data'
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_json(text):
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1, text

    def no_constants(name):
        raise AssertionError(f'non-standard JSON constant {name}')
    return json.loads(lines[0], parse_constant=no_constants)


def assert_png(path):
    path = Path(path)
    assert path.read_bytes()[:8] == PNG_MAGIC
    img = matplotlib.image.imread(str(path))
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


def assert_one_line_error(err, *fragments):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith('bellow-ancf: error: '), err
    for f in fragments:
        assert f in lines[0], err


# -------------------------------------------------------------- help
@pytest.mark.parametrize('argv', [['identify'], ['identify', 'stiffness'], ['identify', 'deff'],
                                  ['identify', 'da'], ['convergence'], ['workspace'],
                                  ['compare-pcc'], ['track']])
def test_every_subcommand_has_help(capsys, argv):
    code, out, _ = run(capsys, *argv, '--help')
    assert code == 0
    assert 'usage: bellow-ancf ' + ' '.join(argv) in out


# ---------------------------------------------------------- identify
def test_identify_stiffness_recovers_the_paper_k(capsys, tmp_path):
    png, yml = tmp_path / 'k.png', tmp_path / 'robot.yaml'
    code, out, err = run(capsys, 'identify', 'stiffness',
                         '--csv', DATA / 'tensile_test_segment.csv', '--plot', png,
                         '--yaml-out', yml, '--json')
    assert code == 0, err
    d = one_json(out)
    k, se = np.array(d['k_coeffs']), np.array(d['k_coeffs_stderr'])
    assert np.all(np.abs(k - [28.9, 576.94]) < 3 * se)
    assert k[1] == pytest.approx(576.94, rel=0.01)
    assert d['f_coeffs'][1] == pytest.approx(5990.4, rel=0.01)
    assert d['l0'] == 0.0963 and d['order'] == 2 and d['r2'] > 0.9999
    assert d['gravity_share_n'] == pytest.approx(0.0327)
    assert d['stage1_ok'] is True
    assert_png(png)
    # the written robot file loads and carries the fit
    cfg = load_robot(str(yml))
    assert cfg.stiffness_coeffs == pytest.approx(tuple(d['k_coeffs']), rel=1e-5)  # 6 digits
    assert cfg.d_eff == load_robot('one_segment').d_eff


def test_identify_stiffness_table_and_order(capsys):
    code, out, _ = run(capsys, 'identify', 'stiffness', '--csv', DATA / 'tensile_test_segment.csv',
                       '--order', '3')
    assert code == 0
    assert 'k(lam)' in out and 'R^2' in out and 'a3' in out and 'k2' in out


def test_identify_deff_recovers_8_087_mm(capsys, tmp_path):
    png = tmp_path / 'deff.png'
    code, out, err = run(capsys, 'identify', 'deff', '--csv', DATA / 'pressure_force.csv',
                         '--plot', png, '--json')
    assert code == 0, err
    d = one_json(out)
    lo, hi = d['d_eff_ci_m']
    assert lo < 8.087e-3 < hi
    assert d['d_eff_m'] == pytest.approx(8.087e-3, rel=0.005)
    assert d['confidence'] == 0.95
    assert_png(png)
    code, out, _ = run(capsys, 'identify', 'deff', '--csv', DATA / 'pressure_force.csv')
    assert code == 0 and 'confidence interval' in out and 'D_eff' in out


def _inline_comments(text):
    """The inline comments (``key: value  # comment``) of a YAML text: (key, comment), in order."""
    return [(line.split(':', 1)[0].strip(' -'), line.split('#', 1)[1].strip())
            for line in text.splitlines() if '#' in line and ':' in line.split('#', 1)[0]]


def _check_comments(text, original, stamped):
    """Every inline comment of ``original`` kept but those of ``stamped`` (key: source)."""
    new, old = _inline_comments(text), _inline_comments(original)
    assert [k for k, _ in new] == [k for k, _ in old]
    for (key, comment), (_, now) in zip(old, new):
        if key not in stamped:
            assert now == comment, key
            continue
        what = comment.rsplit(' (', 1)[0] if comment.endswith(')') else comment
        assert re.fullmatch(re.escape(what) + r' \(identified by bellow-ancf identify '
                            + stamped[key] + r'\)', now), now


@pytest.mark.parametrize('robot', ['one_segment', 'two_segment'])
def test_identify_yaml_out_keeps_the_comments_and_takes_the_file_name(capsys, tmp_path, robot):
    """``identify stiffness`` then ``identify deff`` on its file: values in place, name = file."""
    source = load_robot(robot).source
    original = Path(source).read_text()
    stiff, deff = tmp_path / 'my_robot.yaml', tmp_path / 'lab robot 2.yml'
    code, out, err = run(capsys, 'identify', 'stiffness', '--config', robot,
                         '--csv', DATA / 'tensile_test_segment.csv', '--yaml-out', stiff)
    assert code == 0, err
    assert "robot 'my_robot'" in out
    text = stiff.read_text()
    # every unit comment kept; the identified values' name this run as their source
    # (not '(576.94/5990.4)', the paper's numbers, after a fit to other data)
    day = r' on \d{4}-\d\d-\d\d from '
    stiffness = 'stiffness' + day + re.escape(str(DATA / 'tensile_test_segment.csv'))
    _check_comments(text, original, {'l0_m': stiffness, 'stiffness_coeffs_n_per_m': stiffness})
    assert text.startswith('# Robot description written by `bellow-ancf identify stiffness`')
    cfg = load_robot(str(stiff))
    assert cfg.name == 'my_robot'
    assert cfg.stiffness_coeffs[1] == pytest.approx(576.94, rel=0.01)
    assert cfg.to_dict() | {'name': None, 'actuator': None} == \
        load_robot(robot).to_dict() | {'name': None, 'actuator': None}
    # the deff step reads the stiffness step's file and writes the next one
    code, out, err = run(capsys, 'identify', 'deff', '--config', stiff,
                         '--csv', DATA / 'pressure_force.csv', '--yaml-out', deff, '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['yaml_out'] == str(deff) and d['stage1_ok'] is True
    text = deff.read_text()
    _check_comments(text, original, {
        'l0_m': stiffness, 'stiffness_coeffs_n_per_m': stiffness,   # as the stiffness step wrote
        'd_eff_mm': 'deff' + day + re.escape(str(DATA / 'pressure_force.csv'))})
    assert '(paper V.B)' not in text
    cfg2 = load_robot(str(deff))
    assert cfg2.name == 'lab robot 2'
    assert cfg2.d_eff == pytest.approx(d['d_eff_m'], rel=1e-5)
    assert cfg2.d_eff != load_robot(robot).d_eff
    assert cfg2.stiffness_coeffs == cfg.stiffness_coeffs          # the stiffness step's values
    assert 'identify deff' in text.splitlines()[0]


def test_identify_deff_yaml_out_in_place_and_refused(capsys, tmp_path, monkeypatch):
    """Writing over the --config file works; a D_eff stage 1 refuses writes nothing, exit 1."""
    target = tmp_path / 'robot.yaml'
    target.write_text(Path(load_robot('one_segment').source).read_text())
    code, _, err = run(capsys, 'identify', 'deff', '--config', target,
                       '--csv', DATA / 'pressure_force.csv', '--yaml-out', target)
    assert code == 0, err
    assert load_robot(str(target)).d_eff == pytest.approx(8.087e-3, rel=0.005)
    assert load_robot(str(target)).name == 'robot'
    from bellow_ancf_ros.cli import identify

    def refuse(*args, **kwargs):
        raise ValueError('P -> lam not monotonic (test)')
    monkeypatch.setattr(identify, 'Stage1', refuse)
    out_file = tmp_path / 'never.yaml'
    code, _, err = run(capsys, 'identify', 'deff', '--csv', DATA / 'pressure_force.csv',
                       '--yaml-out', out_file)
    assert code == 1 and not out_file.exists()
    assert 'bellow-ancf: warning: --yaml-out not written' in err and 'test' in err


def test_identify_da_gives_17_90_mm(capsys):
    code, out, err = run(capsys, 'identify', 'da', '--drop-mm', '34.35',
                         '--tip-mass-kg', '0.02397', '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['D_a_m'] == pytest.approx(17.90e-3, abs=5e-6)
    assert d['model_drop_m'] == pytest.approx(34.35e-3, abs=1e-8)
    assert d['n_elements'] == 20 and d['converged'] is True


@pytest.mark.parametrize('argv, fragments', [
    (['identify', 'stiffness', '--csv', 'no/such/file.csv'], ['cannot read file']),
    (['identify', 'deff', '--csv', DATA / 'tensile_test_segment.csv'], ['no pressure column']),
    (['identify', 'stiffness', '--csv', DATA / 'pressure_force.csv'], ['no length change column']),
    (['identify', 'stiffness', '--csv', DATA / 'tensile_test_segment.csv', '--order', '0'],
     ['--order']),
    (['identify', 'da', '--drop-mm', '-3', '--tip-mass-kg', '0.02'], ['--drop-mm']),
    (['identify', 'da', '--drop-mm', '95', '--tip-mass-kg', '0.02'], ['90 %']),
    (['identify'], ['required']),
    (['track', '--trajectory', 'bending_circle'], ['1-segment']),
    (['track', '--trajectory', 'nope'], ['--trajectory']),
    (['workspace', '--config', 'no_such_robot'], ['--config']),
])
def test_bad_input_is_one_line_and_exit_2(capsys, argv, fragments):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert_one_line_error(err, *fragments)


def test_bad_input_as_a_module_subprocess(tmp_path):
    proc = subprocess.run([sys.executable, '-m', 'bellow_ancf_ros.cli', 'identify', 'stiffness',
                           '--csv', str(tmp_path / 'missing.csv')],
                          capture_output=True, text=True, cwd=REPO)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, 'cannot read file')
    assert proc.stdout == ''


# ------------------------------------------------------------- studies
def test_convergence(capsys, tmp_path):
    png = tmp_path / 'conv.png'
    code, out, err = run(capsys, 'convergence', '--max-elements', '6', '--reference', '24',
                         '--repeats', '1', '--plot', png, '--json')
    assert code == 0
    d = one_json(out)
    assert d['recommended_n'] % 3 == 0 and d['recommended_n'] == 3
    rows = {r['n']: r for r in d['rows']}
    assert rows[1]['error_m'] is None
    assert rows[6]['error_m'] < 1e-6 and rows[4]['error_m'] > 1e-5
    assert [n for n, r in rows.items() if r['nodes_on_plates']] == [3, 6]
    assert 'n = 24' in err  # progress on stderr
    assert_png(png)


def test_convergence_table(capsys):
    code, out, err = run(capsys, 'convergence', '--max-elements', '4', '--reference', '12',
                         '--repeats', '1', '--quiet')
    assert code == 0 and err == ''
    assert 'recommended   n = 3' in out and 'nodes on plates' in out


def test_workspace(capsys, tmp_path):
    png, table = tmp_path / 'ws.png', tmp_path / 'ws.csv'
    code, out, err = run(capsys, 'workspace', '--payload-kg', '0', '0.1', '--points', '3',
                         '--plot', png, '--csv', table)
    assert code == 0, err
    assert 'payload' in err  # progress
    assert '18 actuation schemes' in out and out.count('54/54') == 2
    assert_png(png)
    with open(table, newline='') as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 18 * 3
    assert list(rows[0])[:7] == ['payload_kg', 'scheme', 'scheme_name', 'step',
                                 's1_a1_kpa', 's1_a2_kpa', 's1_a3_kpa']
    assert {r['converged'] for r in rows} == {'1'}
    z0 = max(float(r['z_mm']) for r in rows if r['payload_kg'] == '0')
    z1 = max(float(r['z_mm']) for r in rows if r['payload_kg'] == '0.1')
    assert 100 < z1 < z0 < 110
    # the unpressurised-extreme corner: all at p_min is the lowest straight point
    low = [r for r in rows if r['payload_kg'] == '0'
           and r['s1_a1_kpa'] == r['s1_a2_kpa'] == r['s1_a3_kpa'] == '-50']
    assert abs(float(low[0]['x_mm'])) < 1e-6


def test_workspace_two_segment_json(capsys):
    code, out, _ = run(capsys, 'workspace', '--config', 'two_segment', '--points', '3', '--json',
                       '--quiet')
    assert code == 0
    d = one_json(out)
    assert len(d['schemes']) == 4
    assert d['summary'][0]['solved'] == d['summary'][0]['points'] == 12


def test_compare_pcc(capsys, tmp_path):
    png = tmp_path / 'pcc.png'
    code, out, err = run(capsys, 'compare-pcc', '--payload-kg', '0', '0.1', '--points', '3',
                         '--plot', png, '--json', '--quiet')
    assert code == 0, err
    d = one_json(out)
    s = {(r['payload_kg'], r['category']): r for r in d['summary']}
    assert s[(0.1, 'elongation')]['max_m'] > 0.5e-3
    assert s[(0.0, 'bending')]['points'] == 18 * 3
    assert_png(png)
    code, out, _ = run(capsys, 'compare-pcc', '--payload-kg', '0', '--points', '3', '--no-gravity',
                       '--json', '--quiet')
    d = one_json(out)
    el = [r for r in d['summary'] if r['category'] == 'elongation'][0]
    assert el['max_m'] < 1e-9


# --------------------------------------------------------------- track
def test_track_one_segment(capsys, tmp_path):
    png, table = tmp_path / 'track.png', tmp_path / 'p.csv'
    code, out, err = run(capsys, 'track', '--trajectory', 'space_spiral', '--points', '12',
                         '--payload-kg', '0.05', '--csv', table, '--plot', png, '--json')
    assert code == 0, err
    d = one_json(out)
    assert d['reachable_fraction'] == 1.0 and d['points'] == 12
    assert d['position_max_m'] < 1e-9 and d['position_rms_m'] <= d['position_max_m']
    assert d['solve_time_median_s'] <= d['solve_time_p99_s']
    assert_png(png)
    with open(table, newline='') as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ['time_s', 's1_a1_kpa', 's1_a2_kpa', 's1_a3_kpa']
    P = np.array(rows[1:], dtype=float)
    assert P.shape == (12, 4)
    assert np.all(np.diff(P[:, 0]) > 0) and P[0, 0] == 0.0
    assert np.all((P[:, 1:] >= -50) & (P[:, 1:] <= 150))


def test_track_two_segment_table(capsys):
    code, out, _ = run(capsys, 'track', '--trajectory', 'bending_circle',
                       '--config', 'two_segment', '--points', '4', '--bending-angle-deg', '20',
                       '--quiet')
    assert code == 0
    assert 'angle error [deg]' in out and 'reachable     100.0 %' in out
    assert 'bending angle 20 deg' in out


def test_track_unreachable_exits_1(capsys):
    code, out, _ = run(capsys, 'track', '--trajectory', 'planar_circle', '--radius-mm', '60',
                       '--points', '2', '--json', '--quiet')
    assert code == 1
    assert one_json(out)['reachable_fraction'] == 0.0


def test_warm_up_compiles_or_loads_and_names_the_cache(capsys):
    from bellow_ancf_ros import cli
    assert cli.main(['warm-up', '--config', 'one_segment']) == 0
    out, err = capsys.readouterr()
    assert 'numerical kernels' in out and 'cache:' in out
    # progress on stderr: each kernel group of each robot as it starts, with the time so far
    # (and, on a machine slow enough, a heartbeat line while one takes longer than HEARTBEAT_S)
    lines = [x for x in err.strip().splitlines() if ', still (' not in x]
    assert len(lines) == 2, err
    for line, head, group in zip(lines, ('[0/2]', '[1/2]'), ('solver kernels', 'dynamics kernel')):
        assert line.startswith(f'bellow-ancf: warm-up: {head} one_segment: '), line
        assert (f'compiling the {group}' in line or f'loading the {group}' in line), line
        assert line.endswith(' s)'), line
    assert cli.main(['warm-up', '--config', 'one_segment', '--quiet']) == 0
    assert capsys.readouterr().err == ''
    # a bad robot among several: refused before any compilation, on one line
    assert cli.main(['warm-up', '--config', 'one_segment', 'no_such_robot']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('bellow-ancf: error: --config: no_such_robot')


def test_warm_up_says_a_long_compilation_still_runs(monkeypatch):
    """While a kernel group takes longer than the heartbeat, progress lines keep coming."""
    import threading

    from bellow_ancf_ros.cli import warmup
    monkeypatch.setattr(warmup, 'HEARTBEAT_S', 0.01)
    lines, still = [], threading.Event()

    def report(done, total, text):
        lines.append((done, total, text))
        if text.endswith(', still'):
            still.set()

    def work():   # a compilation that lasts until the heartbeat has spoken (or 30 s)
        still.wait(30.0)
        return 'model'
    assert warmup._group(report, 1, 4, 'arm: compiling the dynamics kernel', work) == 'model'
    assert lines[0] == (1, 4, 'arm: compiling the dynamics kernel')
    assert (1, 4, 'arm: compiling the dynamics kernel, still') in lines[1:]
    n = len(lines)   # the heartbeat stops with the group
    assert warmup._group(report, 2, 4, 'arm: loading', lambda: None) is None
    assert lines[n] == (2, 4, 'arm: loading') and all(t != 'arm: compiling the dynamics '
                                                      'kernel, still' for _, _, t in lines[n:])
