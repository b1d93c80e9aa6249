"""CSV and rosbag2 recordings: round trips, settling, and clear errors for bad input."""

import numpy as np
import pytest

from bellow_ancf_ros.core.fit._recordings import (
    Recording,
    RecordingError,
    read_bag,
    read_csv,
    settled_samples,
    write_bag,
    write_csv,
)

pytest.importorskip('rosbags')


def _recording(n=5, A=3, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return Recording(rng.uniform(-50e3, 150e3, (n, A)), rng.normal(size=(n, 3)) * 0.1, q,
                     np.arange(n) * 2.0, source='mem')


def test_csv_round_trip_is_exact(tmp_path):
    rec = _recording()
    path = tmp_path / 'r.csv'
    write_csv(path, rec)
    assert path.read_text().splitlines()[0] == 't_s,p1_kpa,p2_kpa,p3_kpa,x_m,y_m,z_m,qx,qy,qz,qw'
    back = read_csv(path, 3)
    np.testing.assert_allclose(back.pressures_pa, rec.pressures_pa, rtol=1e-15)
    np.testing.assert_array_equal(back.positions_m, rec.positions_m)
    np.testing.assert_allclose(back.quaternions_xyzw, rec.quaternions_xyzw, rtol=1e-15)
    np.testing.assert_array_equal(back.times_s, rec.times_s)


H = 't_s,p1_kpa,p2_kpa,p3_kpa,x_m,y_m,z_m,qx,qy,qz,qw\n'


@pytest.mark.parametrize('text, match', [
    ('', 'empty'),
    ('# only a comment\n', 'empty'),
    ('t_s,p1_kpa,p2_kpa,p3_kpa,x_m,y_m,z_m,qx,qy,qz,qw\n', 'no data rows'),
    ('t,p1,p2,p3,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,0,0,0,1\n', 'expected the header'),
    ('t_s,p1_kpa,p2_kpa,x_m,y_m,z_m,qx,qy,qz,qw\n0,0,0,0,0,0,0,0,0,1\n', 'expected the header'),
    (H + '0,0,0,0,0,0,0,0,0,1\n', 'line 2: expected 11'),
    (H + '0,0,0,abc,0,0,0,0,0,0,1\n', 'not a number'),
    ('t_s,p1_kpa,p2_kpa,p3_kpa,x_m,y_m,z_m,qx,qy,qz,qw\n0,0,0,0,0,0,0,0,0,0,1\n'
     '1,0,nan,0,0,0,0,0,0,0,1\n', 'line 3: not a finite number in column p2_kpa'),
    (H + '0,0,0,0,0,0,0,0,0,0,0\n', 'quaternion is zero'),
])
def test_bad_csv_is_one_clear_line(tmp_path, text, match):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(RecordingError, match=match) as info:
        read_csv(path, 3)
    assert '\n' not in str(info.value)


def test_missing_csv(tmp_path):
    with pytest.raises(RecordingError, match='cannot read file'):
        read_csv(tmp_path / 'nope.csv', 3)


def _streams(dwell=1.0, rate=50.0, overshoot=0.02, seed=1):
    """Three steps (the second republished); poses overshoot for 0.3 s after each change."""
    rng = np.random.default_rng(seed)
    targets = [np.array([10e3, 0.0, -5e3]), np.array([50e3, 20e3, 0.0]), np.zeros(3)]
    poses_true = [np.array([0.01, 0.0, 0.1]), np.array([0.02, -0.01, 0.09]),
                  np.array([0.0, 0.0, 0.1])]
    commands, poses = [], []
    for k, (p, x) in enumerate(zip(targets, poses_true)):
        t0 = k * dwell
        commands.append((t0, p))
        if k == 1:
            commands.append((t0 + 0.5 * dwell, p))      # republished: still the same step
        for t in np.arange(t0, t0 + dwell, 1.0 / rate):
            moving = t - t0 < 0.3
            pos = x + (overshoot if moving else 0.0) + rng.normal(0, 1e-5, 3)
            poses.append((t + 1e-4, pos, np.array([0.0, 0.0, np.sin(0.05), np.cos(0.05)])))
    return commands, poses, targets, poses_true


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('unit', ['Pa', 'kPa'])
def test_bag_round_trip_drops_the_settling_poses(tmp_path, storage, unit):
    commands, poses, targets, poses_true = _streams()
    path = tmp_path / 'bag'
    write_bag(path, commands, poses, storage=storage, unit=unit)
    assert any(p.suffix in ('.db3', '.mcap') for p in path.iterdir())
    rec = read_bag(path, settle_s=0.4, n_actuators=3)
    assert len(rec) == 3
    np.testing.assert_allclose(rec.pressures_pa, targets, atol=1e-9)
    np.testing.assert_allclose(rec.positions_m, poses_true, atol=2e-5)   # no overshoot left
    np.testing.assert_allclose(np.abs(rec.quaternions_xyzw[:, 2]), np.sin(0.05), rtol=1e-12)
    # without settling the overshoot is averaged in
    raw = read_bag(path, settle_s=0.0, drift_tol_m=1.0)
    assert np.max(np.abs(raw.positions_m - poses_true)) > 3e-3


def test_bag_topics_with_and_without_slash_and_missing_topics(tmp_path):
    commands, poses, _, _ = _streams()
    path = tmp_path / 'bag'
    write_bag(path, commands, poses, pressure_topic='/robot/pressure_command',
              pose_topic='/mocap/tip')
    rec = read_bag(path, pose_topic='/mocap/tip', settle_s=0.4)     # namespaced match
    assert len(rec) == 3
    with pytest.raises(RecordingError, match=r"no topic 'measured_pose'.*--pose-topic"):
        read_bag(path, settle_s=0.4)
    with pytest.raises(RecordingError, match='no such bag'):
        read_bag(tmp_path / 'missing')


def test_bag_wrong_actuator_count(tmp_path):
    commands, poses, _, _ = _streams()
    write_bag(tmp_path / 'b', commands, poses)
    with pytest.raises(RecordingError, match='3 pressures, the robot has 6 actuators'):
        read_bag(tmp_path / 'b', n_actuators=6)


def test_poses_that_never_settle_are_refused():
    t = np.arange(0.0, 3.0, 0.02)
    cmd_t = [0.0, 1.0, 2.0]
    cmd_p = [[1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]]
    drifting = np.stack([t * 0.01, 0 * t, 0 * t + 0.1], axis=1)       # 10 mm/s: never at rest
    quat = np.tile([0.0, 0, 0, 1], (len(t), 1))
    with pytest.raises(RecordingError, match='never settle') as info:
        settled_samples(cmd_t, cmd_p, t, drifting, quat, settle_s=0.5)
    assert 'still moved' in str(info.value)
    # a settle time longer than every step leaves no pose either
    with pytest.raises(RecordingError, match='never settle'):
        settled_samples(cmd_t, cmd_p, t, 0 * drifting, quat, settle_s=5.0)
    # at rest, every step is one sample
    rec = settled_samples(cmd_t, cmd_p, t, 0 * drifting, quat, settle_s=0.5)
    assert len(rec) == 3 and not rec.notes


def test_a_swapped_marker_sample_is_dropped_not_averaged_in():
    t = np.arange(0.0, 3.0, 0.01)
    cmd_t = [0.0, 1.0, 2.0]
    cmd_p = [[1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]]
    rng = np.random.default_rng(0)
    pos = np.array([0.01, 0.0, 0.1]) + rng.normal(0.0, 0.15e-3, (len(t), 3))
    quat = np.tile([0.0, 0, 0, 1], (len(t), 1))
    clean = settled_samples(cmd_t, cmd_p, t, pos, quat, settle_s=0.3)
    bad = pos.copy()
    bad[150] += [0.0, 0.02, 0.0]                 # 20 mm off, in the second step's window
    rec = settled_samples(cmd_t, cmd_p, t, bad, quat, settle_s=0.3)
    assert len(rec) == 3
    # the step without it is the mean of one sample less: within the noise of the mean
    assert np.linalg.norm(rec.positions_m[1] - clean.positions_m[1]) < 0.05e-3
    assert any('1 pose(s) farther than 5 mm' in n for n in rec.notes)
    # averaged in, it would have moved that step by 20 mm / 70 samples = 0.29 mm
