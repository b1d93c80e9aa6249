"""``bellow-ancf compliance`` and ``bellow-ancf stiffness`` (issue 20, item 2)."""

import json

import numpy as np
import pytest

from bellow_ancf_ros import cli
from bellow_ancf_ros.core import solve_forward, tip_compliance


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_compliance_json_is_the_cores_at_the_equilibrium(capsys, two):
    F = [0.01, 0.0, -0.02]
    code, out, err = run(capsys, 'compliance', '--config', 'two_segment', '--pressures-kpa',
                         30, 0, 10, 5, 40, 0, '--payload-kg', 0.02, '--tip-force-n', *F,
                         '--json')
    assert code == 0, err
    d = json.loads(out)
    c = tip_compliance(solve_forward(two, [30e3, 0, 10e3, 5e3, 40e3, 0], payload_kg=0.02,
                                     tip_force_n=F))
    for key, ref in (('translational_compliance_m_per_n', c.translational_m_per_n),
                     ('axis_compliance_per_n', c.axis_per_n),
                     ('stiffness_n_per_m', c.stiffness_n_per_m)):
        assert np.array(d[key]).shape == (3, 3)
        np.testing.assert_allclose(d[key], ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    assert d['status'] == 0 and d['stable'] is True


def test_compliance_text_and_a_buckled_equilibrium(capsys):
    code, out, _ = run(capsys, 'compliance', '--pressures-kpa', 0, 0, 0)
    assert code == 0 and 'vertical stiffness' in out and 'mm/N' in out
    # pushed down beyond its buckling load: the status says so, exit 1
    code, out, _ = run(capsys, 'compliance', '--config', 'two_segment', '--pressures-kpa',
                       0, 0, 0, 0, 0, 0, '--tip-force-n', 0, 0, -20, '--json')
    assert code == 1 and json.loads(out)['status'] != 0


def test_stiffness_table_json_plot_and_trajectory(capsys, tmp_path):
    png = tmp_path / 's.png'
    code, out, _ = run(capsys, 'stiffness', '--payload-kg', 0, 0.05, '--levels', 3, '--quiet',
                       '--plot', png, '--json')
    d = json.loads(out)
    assert code == 0 and len(d['rows']) == 6 and png.stat().st_size > 1000
    assert all(r['usable'] and r['vertical_n_per_m'] > 1000 for r in d['rows'])
    code, out, _ = run(capsys, 'stiffness', '--trajectory', 'planar_circle', '--points', 4,
                       '--quiet')
    assert code == 0 and 'vertical (1/C_zz)' in out


def test_three_segments_report_payloads_they_cannot_carry(capsys):
    code, out, _ = run(capsys, 'stiffness', '--config', 'three_segment', '--payload-kg', 0.1,
                       '--levels', 2, '--quiet')
    assert code == 0 and 'no (buckles)' in out


@pytest.mark.parametrize('argv, says', [
    (['compliance', '--pressures-kpa', 0, 0], 'expected 3 pressures'),
    (['compliance', '--pressures-kpa', 0, 0, 0, '--tip-force-n', 2000, 0, 0], 'absurd'),
])
def test_bad_input_is_one_line(capsys, argv, says):
    code, _, err = run(capsys, *argv)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err
