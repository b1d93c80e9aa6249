"""Pose streams (raw recorded motion) and the ring-down window (issue 26)."""

import numpy as np
import pytest

from bellow_ancf_ros.core import geometry
from bellow_ancf_ros.core.fit import (PoseStream, RecordingError, read_pose_stream,
                                      ringdown_window, write_bag)


def test_csv_extra_columns_ignored_pressures_read_bad_rows_dropped(tmp_path):
    path = tmp_path / 's.csv'
    path.write_text('# a comment\nt_s,x_m,y_m,z_m,zx,zy,zz,p1_kpa,p2_kpa\n'
                    '0.1,1,2,3,0,0,1,10,20\n0.0,4,5,6,0,0,1,0,0\n0.2,nan,0,0,0,0,1,1,1\n')
    s = read_pose_stream(csv_path=path)
    np.testing.assert_allclose(s.times_s, [0.0, 0.1])               # sorted, NaN row dropped
    np.testing.assert_allclose(s.positions_m, [[4, 5, 6], [1, 2, 3]])
    assert s.has_pressures and s.notes
    np.testing.assert_allclose(s.pressures_at(0.15), [10e3, 20e3])
    np.testing.assert_allclose(s.pressures_at(-1.0), [0.0, 0.0])


def test_csv_without_pressures_and_its_errors(tmp_path):
    path = tmp_path / 's.csv'
    path.write_text('t_s,x_m,y_m,z_m\n0,0,0,0\n')
    s = read_pose_stream(csv_path=path)
    assert not s.has_pressures and s.pressures_at(0.0) is None and len(s) == 1
    path.write_text('t_s,x_m,y_m\n0,0,0\n')
    with pytest.raises(RecordingError, match='no column z_m'):
        read_pose_stream(csv_path=path)
    path.write_text('t_s,x_m,y_m,z_m\n0,0,0\n')
    with pytest.raises(RecordingError, match='line 2: expected 4 fields'):
        read_pose_stream(csv_path=path)
    with pytest.raises(RecordingError, match='exactly one'):
        read_pose_stream()


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_bag_poses_with_and_without_pressures(tmp_path, storage):
    q = geometry.quaternion_from_rotation(np.eye(3))
    poses = [(1.0 + 0.01 * k, [0.001 * k, 0.0, 0.1], q) for k in range(50)]
    bag = tmp_path / 'b'
    write_bag(bag, [(1.0, [1e3, 2e3, 3e3]), (1.2, [4e3, 5e3, 6e3])], poses, storage=storage,
              unit='kPa')
    s = read_pose_stream(bag_path=bag)
    assert len(s) == 50 and s.frame_id == 'mocap'
    np.testing.assert_allclose(s.positions_m[-1], [0.049, 0.0, 0.1])
    np.testing.assert_allclose(s.pressures_at(1.1), [1e3, 2e3, 3e3])
    np.testing.assert_allclose(s.pressures_at(1.3), [4e3, 5e3, 6e3])
    # a bag of poses alone: no pressures, said so
    only = tmp_path / 'c'
    write_bag(only, [], poses, storage=storage)
    s = read_pose_stream(bag_path=only)
    assert not s.has_pressures and any('pressure_command' in n for n in s.notes)


def test_ringdown_window_starts_half_a_period_after_the_motion():
    t = np.arange(0.0, 3.0, 1 / 120)
    f, zeta, t_rel = 4.0, 0.05, 0.5
    w = 2 * np.pi * f
    tau = np.clip(t - t_rel, 0.0, None)
    wd = w * np.sqrt(1 - zeta ** 2)
    x = 0.004 * np.exp(-zeta * w * tau) * (np.cos(wd * tau)
                                           + zeta / np.sqrt(1 - zeta ** 2) * np.sin(wd * tau))
    pos = np.column_stack([x, 0.5 * x, np.full_like(x, 0.1)])
    win = ringdown_window(t, pos)
    assert t_rel <= win.t_motion_s < t_rel + 0.12 / f   # a tenth of 2 A: 0.1 period
    assert win.frequency_hz == pytest.approx(f * np.sqrt(1 - zeta ** 2), rel=0.01)
    assert win.t_start_s == pytest.approx(win.t_motion_s + 0.5 / win.frequency_hz)
    with pytest.raises(ValueError, match='does not move'):
        ringdown_window(t, np.zeros((len(t), 3)))
    with pytest.raises(ValueError, match='samples in the window'):   # too short to fit
        ringdown_window(t, pos, t_end_s=t_rel + 0.55 / f)


def test_pose_stream_sorts_and_shapes():
    s = PoseStream([2.0, 1.0], [[1, 1, 1], [0, 0, 0]])
    np.testing.assert_allclose(s.times_s, [1.0, 2.0])
    assert s.pressures_pa.shape == (0, 0) and not s.has_pressures
