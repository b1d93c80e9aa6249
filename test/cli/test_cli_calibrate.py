"""``bellow-ancf calibrate``: CSV and bags (sqlite3, mcap) in; robot file, JSON, plot out."""

import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import calibration_data as cd
from bellow_ancf_ros import cli
from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.fit._excitation import excitation_sequence
from bellow_ancf_ros.core.fit._recordings import csv_header, write_bag, write_csv

pytest.importorskip('rosbags')


@pytest.fixture(scope='module')
def recorded(one_cfg):
    """A small recording of the mismatched one-segment robot (and the true robot)."""
    true_cfg, _ = cd.mismatch(one_cfg)
    rec, _, _ = cd.recording(true_cfg, excitation_sequence(one_cfg, 2, 6, seed=3))
    return rec.subset(slice(None, None, 3))


def _run(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _bag(path, rec, storage, unit='Pa'):
    commands = [(k * 2.0, p) for k, p in enumerate(rec.pressures_pa)]
    poses = [(k * 2.0 + dt, x + (0.02 if dt < 0.5 else 0.0), q)
             for k, (x, q) in enumerate(zip(rec.positions_m, rec.quaternions_xyzw))
             for dt in (0.2, 1.0, 1.5)]
    write_bag(path, commands, poses, storage=storage, unit=unit)
    return path


def test_csv_to_robot_file_json_and_plot(tmp_path, capsys, recorded):
    csv_path = tmp_path / 'rec.csv'
    write_csv(csv_path, recorded)
    out, png = tmp_path / 'cal.yaml', tmp_path / 'res.png'
    code, stdout, err = _run(capsys, 'calibrate', '--config', 'one_segment',
                             '--csv', str(csv_path), '--out', str(out), '--plot', str(png),
                             '--json')
    assert code == 0, err
    d = json.loads(stdout.strip().splitlines()[-1])
    assert set(d['parameters']) == {'segments[0].pitch_radius_mm', 'actuator.d_a_mm',
                                    'actuator.d_eff_mm', 'stiffness_scale'}
    for p in d['parameters'].values():
        assert set(p) >= {'value', 'std_error'} and p['std_error'] > 0
    assert d['samples'] == len(recorded)
    assert d['rmse_after_mm'] < d['rmse_before_mm']
    np.testing.assert_allclose(d['frame']['translation_m'], cd.FRAME_T, atol=1e-3)
    assert abs(np.linalg.norm(d['frame']['quaternion_xyzw']) - 1) < 1e-12
    # the robot file loads (nodes use load_robot for robot_config) and carries provenance
    cfg = load_robot(out)
    text = out.read_text()
    assert str(csv_path) in text and 'RMSE' in text
    assert cfg.name == 'cal'                             # named after the written file
    assert cfg.segments[0].pitch_radius * 1e3 == pytest.approx(
        d['parameters']['segments[0].pitch_radius_mm']['value'], rel=1e-12)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # the nominal file's unit comments stay; a fitted value's names this calibration as its
    # source instead of the nominal one (no '(paper V.C)', '(assumed)' beside fitted values)
    source = (r' \(calibrated by bellow-ancf calibrate on \d{4}-\d\d-\d\d from '
              + re.escape(str(csv_path)) + r'\)$')
    line = {ln.split(':')[0].strip(' -'): ln for ln in text.splitlines() if '#' in ln}
    for key, comment in (('d_a_mm', '# cross-sectional diameter for bending [mm]'),
                         ('d_eff_mm', '# effective actuation diameter [mm]'),
                         ('pitch_radius_mm', '# radius of the actuator circle [mm]'),
                         ('stiffness_coeffs_n_per_m', '[N/m], ascending powers')):
        assert re.search(re.escape(comment) + source, line[key]), line[key]
    assert '(paper V.C)' not in text and '(paper V.B)' not in text
    assert line['linear_density_kg_per_m'].endswith('[kg/m] (assumed)')   # not fitted: as it was
    d_a_line = next(line for line in text.splitlines() if line.strip().startswith('d_a_mm:'))
    assert float(d_a_line.split(':')[1].split('#')[0]) == pytest.approx(
        d['parameters']['actuator.d_a_mm']['value'], rel=1e-12)
    # the fitted transform is machine-readable: mocap_frame, and it undoes the offset
    mf = cfg.mocap_frame
    assert mf is not None and mf.frame_id == 'world'   # a CSV names no frame: the default
    np.testing.assert_allclose(mf.position, d['frame']['translation_m'], atol=1e-9)
    R = Rotation.from_rotvec(np.radians(cd.FRAME_ROTVEC_DEG)).as_matrix()
    p_base = np.array([0.01, -0.02, 0.1])
    p_back, q_back = mf.to_base(R @ p_base + cd.FRAME_T, Rotation.from_matrix(R).as_quat())
    np.testing.assert_allclose(p_back, p_base, atol=1e-3)   # the fit's own error (noise)
    assert abs(abs(q_back[3]) - 1.0) < 1e-4
    # the stage-1 coupling of D_eff and the stiffness scale is named on stderr
    assert 'warning: actuator.d_eff_mm and stiffness_scale cannot be separated' in err


@pytest.mark.parametrize('storage, unit', [('sqlite3', 'kPa'), ('mcap', 'Pa')])
def test_bag_storages(tmp_path, capsys, recorded, storage, unit):
    bag = _bag(tmp_path / 'bag', recorded, storage, unit)
    code, stdout, err = _run(capsys, 'calibrate', '--config', 'one_segment', '--bag', str(bag),
                             '--fit', 'actuator.d_a_mm', '--json')
    assert code == 0, err
    d = json.loads(stdout.strip().splitlines()[-1])
    assert d['samples'] == len(recorded)
    assert d['rmse_after_mm'] < d['rmse_before_mm']
    np.testing.assert_allclose(d['frame']['translation_m'], cd.FRAME_T, atol=1e-3)
    # a bag names its frame: it is the robot file's mocap frame
    out = tmp_path / 'cal.yaml'
    code, _, err = _run(capsys, 'calibrate', '--config', 'one_segment', '--bag', str(bag),
                        '--fit', 'actuator.d_a_mm', '--out', str(out))
    assert code == 0, err
    assert load_robot(out).mocap_frame.frame_id == 'mocap'   # write_bag's frame_id


def test_table_output(tmp_path, capsys, recorded):
    csv_path = tmp_path / 'rec.csv'
    write_csv(csv_path, recorded)
    code, stdout, _ = _run(capsys, 'calibrate', '--config', 'one_segment', '--csv', str(csv_path),
                           '--fit', 'actuator.d_a_mm')
    assert code == 0
    assert 'actuator.d_a_mm' in stdout and 'position RMSE' in stdout and '95 % interval' in stdout


def _bad_csv(tmp_path, text):
    p = tmp_path / 'bad.csv'
    p.write_text(text)
    return ['--csv', str(p)]


HEADER = ','.join(csv_header(3)) + '\n'


@pytest.mark.parametrize('make, match', [
    (lambda tp, rec: _bad_csv(tp, ''), 'empty'),
    (lambda tp, rec: _bad_csv(tp, 'a,b\n1,2\n'), 'expected the header'),
    (lambda tp, rec: _bad_csv(tp, HEADER + '0,1,2\n'), 'line 2: expected 11 fields'),
    (lambda tp, rec: _bad_csv(tp, HEADER + '0,0,0,0,0,0,nan,0,0,0,1\n'), 'line 2: not a finite'),
    (lambda tp, rec: _bad_csv(tp, HEADER + '0,0,0,0,0,0,0.1,0,0,0,1\n' * 9), 'need at least 10'),
    (lambda tp, rec: ['--bag', str(tp / 'nothing')], 'no such bag'),
    (lambda tp, rec: ['--bag', str(_bag(tp / 'b', rec, 'sqlite3')), '--pose-topic', 'tip'],
     "no topic 'tip'"),
    (lambda tp, rec: ['--bag', str(_bag(tp / 'b', rec, 'mcap')), '--settle-s', '5'],
     'never settle'),
    (lambda tp, rec: ['--csv', 'x.csv', '--fit', 'actuator.nope'], 'not a scalar parameter'),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, recorded, make, match):
    code, stdout, err = _run(capsys, 'calibrate', '--config', 'one_segment',
                             *make(tmp_path, recorded))
    assert code == 2
    assert match in err
    assert len(err.strip().splitlines()) == 1 and 'Traceback' not in err
    assert err.startswith('bellow-ancf: error: ')


def test_bag_without_the_topics(tmp_path, capsys):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    with Writer(tmp_path / 'other', version=9) as w:
        c = w.add_connection('/chatter', 'std_msgs/msg/String', typestore=store)
        w.write(c, 1, store.serialize_cdr(store.types['std_msgs/msg/String'](data='hi'),
                                          'std_msgs/msg/String'))
    code, _, err = _run(capsys, 'calibrate', '--config', 'one_segment', '--bag',
                        str(tmp_path / 'other'))
    assert code == 2 and "no topic 'pressure_command'" in err and '/chatter' in err


@pytest.mark.parametrize('sim_time', [False, True])
def test_record_writes_a_bag_calibrate_reads(tmp_path, ros_context, sim_time):
    """``bellow-ancf record`` (no rosbag2): commands and poses in, a bag calibrate reads out.

    With ``--use-sim-time`` the reception times are a ``/clock``'s (here one at
    0.25x real time from 100 s, as a simulation or a bag played with
    ``--clock``), and the poses' simulation-time stamps match them.
    """
    import os
    import subprocess
    import sys
    import threading
    import time

    rclpy = pytest.importorskip('rclpy')
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    from bellow_ancf_ros.core.fit import read_bag

    from rclpy.time import Time
    from rosgraph_msgs.msg import Clock

    node = rclpy.create_node('record_source', context=ros_context)
    pub_p = node.create_publisher(Float64MultiArray, 'pressure_command', 10)
    pub_x = node.create_publisher(PoseStamped, 'measured_pose', 10)
    pub_c = node.create_publisher(Clock, '/clock', 10)
    stop = threading.Event()
    t0 = time.monotonic()

    def now():
        if not sim_time:
            return node.get_clock().now()
        return Time(nanoseconds=int((100.0 + 0.25 * (time.monotonic() - t0)) * 1e9))

    def publish():
        k = 0
        while not stop.is_set():
            pub_c.publish(Clock(clock=now().to_msg()))
            # (steps of 1 s; a slow start of the recorder on a busy machine: held at 90 kPa)
            m = Float64MultiArray(data=[10e3 * min(k // 20, 9), 0.0, 0.0])
            m.layout.dim = [MultiArrayDimension(label='actuator_pressure_gauge_pa', size=3,
                                                stride=3)]
            pub_p.publish(m)
            x = PoseStamped()
            x.header.frame_id = 'world'
            x.header.stamp = now().to_msg()
            x.pose.position.z = 0.1 + 1e-3 * (k // 20)
            x.pose.orientation.w = 1.0
            pub_x.publish(x)
            k += 1
            time.sleep(0.05)
    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    bag = tmp_path / 'bag'
    try:
        res = subprocess.run([sys.executable, '-m', 'bellow_ancf_ros.cli', 'record', '--out',
                              str(bag), '--duration', '4', '--storage', 'mcap']
                             + (['--use-sim-time'] if sim_time else []),
                             env=dict(os.environ), capture_output=True, text=True, timeout=60)
    finally:
        stop.set()
        thread.join(5)
        node.destroy_node()
    assert res.returncode == 0, res.stderr
    assert 'recorded: /pressure_command' in res.stdout
    rec = read_bag(bag, settle_s=0.2, n_actuators=3)
    assert len(rec) >= 2 and rec.frame_id == 'world'
    assert set(np.round(rec.pressures_pa[:, 0] / 10e3)) <= set(range(10))
    if sim_time:   # every reception time on the /clock, just after the pose's stamp
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            got = [(c.topic, t, reader.deserialize(raw, c.msgtype))
                   for c, t, raw in reader.messages()]
        end = 100.0 + 0.25 * (time.monotonic() - t0)
        assert all(100.0 <= t * 1e-9 <= end for _, t, _ in got)
        lag = [t * 1e-9 - (m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
               for topic, t, m in got if topic == '/measured_pose']
        assert len(lag) > 10 and -0.02 <= min(lag) and max(lag) <= 0.1, (min(lag), max(lag))


def test_values_in_place_keeps_layout_and_reads_back(one_cfg):
    """The calibrated file: the nominal text, its comments, the new values; else a plain dump."""
    import yaml

    from bellow_ancf_ros.cli.output import values_in_place as _values_in_place

    for name in ('one_segment', 'two_segment'):
        cfg = load_robot(name)
        original = open(cfg.source).read()
        d = cfg.to_dict()
        d['name'] = f'{name}_calibrated'
        d['actuator']['stiffness_coeffs_n_per_m'] = [30.1, 580.5]
        d['segments'][-1]['top_plate_mass_kg'] = 0.0123
        d['mocap_frame'] = {'frame_id': 'world', 'position_m': [0.1, 0.2, 0.3],
                            'quaternion_xyzw': [0.0, 0.0, 0.0, 1.0]}
        text = _values_in_place(original, d)
        assert yaml.safe_load(text) == yaml.safe_load(yaml.safe_dump(d))
        assert load_robot(name).to_dict()['payload_kg'] == yaml.safe_load(text)['payload_kg']
        kept = [c for c in original.splitlines() if '# ' in c and ':' in c.split('#')[0]]
        for line in kept:   # every inline comment of the original is still there
            assert line.split('#', 1)[1] in text
    # a text it cannot follow: None (the caller dumps)
    assert _values_in_place('name: [unexpected\n', d) is None


def test_rewritten_robot_file_has_no_stale_comment():
    """A changed or fitted value's comment names the new source; the others stay as they were."""
    from bellow_ancf_ros.cli.output import values_in_place as _values_in_place

    cfg = load_robot('two_segment')
    original = open(cfg.source).read()
    d = cfg.to_dict()
    d['name'] = 'lab_arm'
    d['actuator']['d_eff_mm'] = 8.2                        # changed: '(paper V.B)' is stale
    d['segments'][1]['top_plate_mass_kg'] = 0.0123         # changed, had no comment
    note = 'calibrated by bellow-ancf calibrate on 2030-01-02 from rec.csv'
    text = _values_in_place(original, d, note, ['segments[*].pitch_radius_mm'])  # same values
    lines = text.splitlines()

    def line(key, n=0):
        return [ln for ln in lines if ln.strip(' -').startswith(key + ':')][n]
    assert line('d_eff_mm').endswith('# effective actuation diameter [mm] (' + note + ')')
    assert '(paper V.B)' not in text
    assert line('pitch_radius_mm', 0).endswith('# radius of the actuator circle [mm] ('
                                               + note + ')')   # fitted to the same value
    assert line('pitch_radius_mm', 1).endswith('0  # (' + note + ')')
    assert line('top_plate_mass_kg', 1).endswith('0.0123  # (' + note + ')')
    assert line('top_plate_mass_kg', 0).endswith('# mass of the top plate [kg]')
    assert line('d_a_mm').endswith('[mm] (paper V.C)')      # neither fitted nor changed
    assert line('l0_m').endswith('[m] (576.94/5990.4)')
    assert line('name') == 'name: lab_arm'
    assert text.count(note) == 4
    # without a note (no command to name), the comments are the original's
    plain = _values_in_place(original, d)
    assert '(paper V.B)' in plain and note not in plain


def test_a_d_eff_identify_deff_measured_is_kept_out_of_the_default_fit(tmp_path, capsys):
    """The README's "Your own robot": identify deff on its rig, then calibrate on its bag.

    The poses cannot tell ``D_eff`` from ``stiffness_scale`` (correlation
    +0.999): fitted together, an identified 8.083 mm went to 7.62 mm and the
    scale to 0.80 (the robot's: 0.90).  The default keys now keep the
    measured one, and the scale comes out at the robot's.
    """
    from pathlib import Path
    repo = Path(__file__).resolve().parents[2]
    mine = tmp_path / 'my_robot.yaml'
    mine.write_text(Path(load_robot('one_segment').source).read_text())
    code, _, err = _run(capsys, 'identify', 'deff', '--config', str(mine), '--yaml-out',
                        str(mine), '--csv', str(repo / 'data' / 'pressure_force.csv'))
    assert code == 0, err
    identified = load_robot(str(mine)).d_eff
    code, out, err = _run(capsys, 'calibrate', '--config', str(mine), '--bag',
                          str(repo / 'data' / 'one_segment_bag'), '--json')
    assert code == 0, err
    assert (f'actuator.d_eff_mm stays at {identified * 1e3:g} mm, as identify deff measured '
            'it') in err
    got = json.loads(out.strip().splitlines()[-1])['parameters']
    assert 'actuator.d_eff_mm' not in got
    assert got['stiffness_scale']['value'] == pytest.approx(0.90, abs=0.01)
    # a file whose D_eff nobody measured: the default keys as before
    code, out, err = _run(capsys, 'calibrate', '--config', 'one_segment', '--bag',
                          str(repo / 'data' / 'one_segment_bag'), '--json')
    assert code == 0 and 'stays at' not in err
    assert 'actuator.d_eff_mm' in json.loads(out.strip().splitlines()[-1])['parameters']
