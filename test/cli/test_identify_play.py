"""``bellow-ancf identify play``: the regulators' play from their own sensors (CSV and bag).

The recordings are the simulated regulators' (dead time, play, lag) fed a
staircase of set-points on every actuator (10 to 40 kPa, up and down twice,
each held 1 s), sampled at 100 Hz on a clock that starts at 100 s.
"""

import csv
import json

import numpy as np
import pytest

from bellow_ancf_ros.core.fit import (play_staircase, pressure_csv_header, staircase_recording,
                                      write_bag)
from bellow_ancf_ros.core.sim import PressureRegulators
from test_cli import assert_one_line_error, run   # (the CLI tests' helpers)

PLAY_PA = (1200.0, 900.0, 1500.0)
CLOCK_S = 100.0


def record(plays=PLAY_PA, moving=(True, True, True)):
    """``(t, set-points (n, 3), measured (n, 3))``: the staircase through three regulators."""
    starts, levels = play_staircase(10e3, 40e3)
    runs = [staircase_recording(
        PressureRegulators(1, -50e3, 150e3, 0.07, dead_time_s=0.02, hysteresis_pa=h),
        starts, levels if moves else np.full_like(levels, 20e3))
        for h, moves in zip(plays, moving)]
    return (CLOCK_S + runs[0][0], np.column_stack([r[1] for r in runs]),
            np.column_stack([r[2][:, 0] for r in runs]))


def write_csv(path, t, sent, measured):
    with open(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(pressure_csv_header(3))
        for row in zip(t, sent / 1e3, measured / 1e3):
            w.writerow([row[0], *row[1], *row[2]])


def test_csv_gives_each_regulators_play_and_the_node_parameter(tmp_path, capsys):
    path = tmp_path / 'regulators.csv'
    write_csv(path, *record())
    code, out, err = run(capsys, 'identify', 'play', '--csv', path, '--json')
    assert code == 0, err
    got = json.loads(out)
    widths = [a['width_pa'] for a in got['actuators']]
    np.testing.assert_allclose(widths, PLAY_PA, atol=5.0)
    assert got['regulator_play_kpa'] == pytest.approx(min(widths) / 1e3)
    code, out, _ = run(capsys, 'identify', 'play', '--csv', path)
    assert 'actuator 2     play 0.900 kPa' in out
    assert 'regulator_play_kpa 0.900: inverse node parameter regulator_play_kpa' in out


def test_bag_of_the_nodes_topics_gives_the_same(tmp_path, capsys):
    """Set-points on pressure_command (kPa), sensors on measured_pressure: the newest before."""
    t, sent, measured = record()
    changes = np.flatnonzero(np.any(np.diff(sent, axis=0) != 0, axis=1)) + 1
    commands = [(t[0] - 0.005, sent[0])] + [(t[i] - 0.005, sent[i]) for i in changes]
    bag = tmp_path / 'bag'
    write_bag(bag, commands, [], unit='kPa', measured=list(zip(t, measured)))
    code, out, err = run(capsys, 'identify', 'play', '--bag', bag, '--json')
    assert code == 0, err
    widths = [a['width_pa'] for a in json.loads(out)['actuators']]
    np.testing.assert_allclose(widths, PLAY_PA, atol=5.0)


def test_an_actuator_held_still_is_named_and_the_others_count(tmp_path, capsys):
    path = tmp_path / 'regulators.csv'
    write_csv(path, *record(moving=(True, False, True)))
    code, out, err = run(capsys, 'identify', 'play', '--csv', path)
    assert code == 0, err
    assert 'actuator 2     no play read: fit_play needs settled holds' in out
    assert 'regulator_play_kpa 1.200' in out


def test_bad_recordings_are_one_line_errors(tmp_path, capsys):
    still = tmp_path / 'still.csv'
    write_csv(still, *record(moving=(False, False, False)))
    code, _, err = run(capsys, 'identify', 'play', '--csv', still)
    assert code == 2
    assert_one_line_error(err, 'no play from this recording: actuator 1: fit_play needs')
    bad = tmp_path / 'bad.csv'
    bad.write_text('t_s,p1_kpa,x_m\n0,1,2\n')
    code, _, err = run(capsys, 'identify', 'play', '--csv', bad)
    assert code == 2
    assert_one_line_error(err, '--csv', 'expected the header t_s,p1_kpa,m1_kpa')
    bag = tmp_path / 'bag'
    write_bag(bag, [(0.0, np.zeros(3))], [])
    code, _, err = run(capsys, 'identify', 'play', '--bag', bag)
    assert code == 2
    assert_one_line_error(err, "--bag", "no topic 'measured_pressure'")
