"""Calibration recordings: CSV files and rosbag2 directories (read and write).

A recording is a list of quasi-static *samples*: the gauge pressures of all
actuators (Pa, the project's actuator order: segment by segment, actuator 1,
2, 3 within a segment) and the end-effector pose measured by the motion-capture
system, in the motion-capture system's own frame (position in m, orientation
as a unit quaternion ``x, y, z, w``).

* CSV (:func:`read_csv`, :func:`write_csv`): header
  ``t_s,p1_kpa,...,pN_kpa,x_m,y_m,z_m,qx,qy,qz,qw``, one row per settled
  sample, pressures in kPa gauge.
* rosbag2 (:func:`read_bag`, :func:`write_bag`), sqlite3 or mcap storage, as
  ``ros2 bag record /pressure_command /measured_pose`` writes it; read and
  written with the pure-Python ``rosbags`` library (no ROS install needed).
  ``pressure_command`` is ``std_msgs/Float64MultiArray`` whose
  ``layout.dim[0].label`` names the unit (``actuator_pressure_gauge_pa`` or
  ``..._kpa``; no label: Pa), ``measured_pose`` is
  ``geometry_msgs/PoseStamped`` in the motion-capture frame.  Times are the
  bag's receive times.  :func:`settled_samples` turns the two streams into
  samples: a command that repeats the previous one continues its step; poses
  within ``settle_s`` after a command change are dropped, and so are outliers
  (a swapped marker: farther than :data:`OUTLIER_M` from the median of the
  five poses around it; a smooth motion is no outlier); the rest of the step
  is averaged (position mean,
  sign-aligned normalised quaternion mean); a step whose poses still drift
  (first half and second half of the kept poses differ by more than
  ``drift_tol_m``) is dropped as not settled.

A *pose stream* (:class:`PoseStream`, :func:`read_pose_stream`) is the raw
motion instead: every pose as recorded (a release or a step ringing down),
with the pressures where the recording has them.  CSV: columns ``t_s, x_m,
y_m, z_m`` and optionally ``p1_kpa ... pN_kpa`` (other columns, such as the
z-axis or a quaternion, are ignored; ``bellow-ancf simulate --csv`` writes
such a file); bag: every ``measured_pose`` message (times: the header
stamps, the capture times, when all are set, else the receive times) and
``pressure_command`` when the bag has it.

A *pressure recording* (:class:`PressureRecording`,
:func:`read_pressure_recording`) holds the regulators' own pressure sensors
and the set-points in effect (what :func:`~._regulator_play.fit_play`
reads): CSV columns ``t_s, p1_kpa ... pN_kpa, m1_kpa ... mN_kpa`` (set-point
and measured pressure of each actuator, one row per measured sample); bag:
every ``measured_pressure`` message (``std_msgs/Float64MultiArray``, the
regulator driver's readings, units as ``pressure_command``'s), with the
newest ``pressure_command`` received before it (receive times).

Every problem is a :class:`RecordingError` (a ``ValueError``) with a one-line
message naming the file, line or topic.  No ROS import.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..geometry import quaternion_mean

__all__ = [
    'RecordingError', 'Recording', 'csv_header', 'read_csv', 'write_csv', 'settled_samples',
    'read_bag', 'write_bag', 'read_recording', 'PRESSURE_TOPIC', 'POSE_TOPIC',
    'FLOAT64_MULTI_ARRAY', 'POSE_STAMPED', 'pressure_unit', 'BagWriter', 'PoseStream',
    'numeric_csv_rows',
    'read_pose_stream', 'read_pose_stream_csv', 'read_pose_stream_bag', 'POSE_STREAM_COLUMNS',
    'MEASURED_PRESSURE_TOPIC', 'PressureRecording', 'pressure_csv_header',
    'read_pressure_recording',
]

PRESSURE_TOPIC = 'pressure_command'
#: The topic a regulator driver publishes its pressure sensors' readings on.
MEASURED_PRESSURE_TOPIC = 'measured_pressure'
POSE_TOPIC = 'measured_pose'
FLOAT64_MULTI_ARRAY = 'std_msgs/msg/Float64MultiArray'
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
_UNITS = {'Pa': 1.0, 'kPa': 1e3}
_POSE_COLUMNS = ('x_m', 'y_m', 'z_m', 'qx', 'qy', 'qz', 'qw')
_MIN_QUAT_NORM = 1e-6


class RecordingError(ValueError):
    """A recording that cannot be used (one-line message naming the problem)."""


@dataclass
class Recording:
    """Quasi-static samples: pressures [Pa] and measured poses in the mocap frame.

    ``quaternions_xyzw`` are unit quaternions; ``times_s`` the time of each
    sample (CSV: the file's ``t_s``; bag: the start of the averaged window).
    ``notes`` say what a reader dropped.  ``frame_id``: the mocap frame's
    name where the recording says it (a bag's pose ``header.frame_id``; '' for
    a CSV file).
    """

    pressures_pa: np.ndarray
    positions_m: np.ndarray
    quaternions_xyzw: np.ndarray
    times_s: np.ndarray
    source: str = ''
    notes: list = field(default_factory=list)
    frame_id: str = ''

    def __post_init__(self) -> None:
        self.pressures_pa = np.atleast_2d(np.asarray(self.pressures_pa, dtype=float))
        self.positions_m = np.asarray(self.positions_m, dtype=float).reshape(-1, 3)
        self.quaternions_xyzw = np.asarray(self.quaternions_xyzw, dtype=float).reshape(-1, 4)
        self.times_s = np.asarray(self.times_s, dtype=float).ravel()
        n = len(self.positions_m)
        if not (len(self.pressures_pa) == len(self.quaternions_xyzw) == len(self.times_s) == n):
            raise RecordingError('pressures, positions, quaternions and times differ in length')

    def __len__(self) -> int:
        return len(self.positions_m)

    @property
    def n_actuators(self) -> int:
        """Number of pressures per sample."""
        return self.pressures_pa.shape[1]

    def subset(self, index) -> 'Recording':
        """The samples ``index`` (array of indices or a boolean mask)."""
        return Recording(self.pressures_pa[index], self.positions_m[index],
                         self.quaternions_xyzw[index], self.times_s[index], self.source,
                         list(self.notes), self.frame_id)


# ------------------------------------------------------------------- CSV
def csv_header(n_actuators: int) -> list[str]:
    """``t_s, p1_kpa, ..., pN_kpa, x_m, y_m, z_m, qx, qy, qz, qw``."""
    return ['t_s'] + [f'p{i + 1}_kpa' for i in range(n_actuators)] + list(_POSE_COLUMNS)


def _unit_quaternions(q: np.ndarray, where) -> np.ndarray:
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~(norm > _MIN_QUAT_NORM))
    if bad.size:
        raise RecordingError(f'{where(int(bad[0]))}: the orientation quaternion is zero')
    return q / norm[:, None]


def numeric_csv_rows(path, check_header, error=RecordingError, label: str | None = None):
    """``(header, [(line number, values), ...])`` of a numeric CSV file.

    Blank lines and ``#`` comment lines are skipped; the first other row is
    the header (lower case, stripped), handed to ``check_header(header, line)``
    (which raises for a bad one); every later row must have as many fields
    and hold numbers (NaN and inf pass: the caller decides).  Every problem is
    ``error`` with one line naming ``label`` (default the path) and the line.
    The header is None for a file without one.
    """
    label = str(path) if label is None else label
    try:
        fh = open(path, newline='', encoding='utf-8-sig')
    except OSError as exc:
        raise error(f'{label}: cannot read file: {exc.strerror or exc}') from None
    header, rows = None, []
    with fh:
        reader = csv.reader(fh)
        try:
            for row in reader:
                cells = [c.strip() for c in row]
                if not any(cells) or cells[0].startswith('#'):
                    continue
                line = reader.line_num
                if header is None:
                    header = [c.lower() for c in cells]
                    check_header(header, line)
                    continue
                if len(cells) != len(header):
                    raise error(f'{label}, line {line}: expected {len(header)} fields, '
                                f'got {len(cells)}')
                try:
                    rows.append((line, [float(c) for c in cells]))
                except ValueError:
                    raise error(f'{label}, line {line}: not a number in '
                                f'{",".join(cells)!r}') from None
        except (csv.Error, UnicodeDecodeError) as exc:
            raise error(f'{label}, line {reader.line_num}: malformed CSV: {exc}') from None
    return header, rows


def read_csv(path, n_actuators: int | None = None) -> Recording:
    """Read a CSV recording (see the module doc); ``n_actuators`` checks the header."""
    label = str(path)
    header, records = numeric_csv_rows(
        path, lambda h, line: _check_header(h, n_actuators, label, line))
    rows, lines = [], []
    for line, values in records:
        bad = [header[i] for i, v in enumerate(values) if not math.isfinite(v)]
        if bad:
            raise RecordingError(f'{label}, line {line}: not a finite number in column '
                                 f'{bad[0]} (NaN or inf)')
        rows.append(values)
        lines.append(line)
    if header is None:
        raise RecordingError(f'{label}: the file is empty (expected the header '
                             f'{",".join(csv_header(n_actuators or 3))})')
    if not rows:
        raise RecordingError(f'{label}: no data rows after the header')
    data = np.array(rows)
    n_p = len(header) - 1 - len(_POSE_COLUMNS)
    quat = _unit_quaternions(data[:, 1 + n_p + 3:], lambda i: f'{label}, line {lines[i]}')
    return Recording(data[:, 1:1 + n_p] * 1e3, data[:, 1 + n_p:1 + n_p + 3], quat, data[:, 0],
                     source=label)


def _check_header(header, n_actuators, label, line) -> None:
    n_p = len(header) - 1 - len(_POSE_COLUMNS)
    expected = csv_header(n_actuators if n_actuators is not None else max(n_p, 1))
    if header != expected:
        raise RecordingError(f'{label}, line {line}: expected the header {",".join(expected)}, '
                             f'got {",".join(header)}')


def write_csv(path, recording: Recording) -> None:
    """Write ``recording`` as a CSV file (kPa, m, quaternion x y z w)."""
    with open(path, 'w', newline='', encoding='utf-8') as fh:
        w = csv.writer(fh)
        w.writerow(csv_header(recording.n_actuators))
        for t, p, x, q in zip(recording.times_s, recording.pressures_pa, recording.positions_m,
                              recording.quaternions_xyzw):
            w.writerow([repr(float(t))] + [repr(float(v)) for v in p / 1e3]
                       + [repr(float(v)) for v in x] + [repr(float(v)) for v in q])


# --------------------------------------------------------- settled samples
#: A pose this far from the median of the five around it is an outlier [m] (the loop's gate).
OUTLIER_M = 0.005


def samples_around(x: np.ndarray, half_width: int) -> np.ndarray:
    """The ``2 half_width + 1`` samples (rows of ``x``) around each, the ends repeated.

    Shape ``(len(x), 2 half_width + 1) + x.shape[1:]``; its median over axis 1
    is the running median the pose-stream fits use against outliers.
    """
    n = len(x)
    offsets = np.arange(-half_width, half_width + 1)
    return x[np.clip(np.arange(n)[:, None] + offsets[None, :], 0, n - 1)]


def _not_spikes(pos: np.ndarray) -> np.ndarray:
    """True for the poses within :data:`OUTLIER_M` of the median of the five around them."""
    med = np.median(samples_around(pos, 2), axis=1)
    return np.linalg.norm(pos - med, axis=1) <= OUTLIER_M


def settled_samples(cmd_t, cmd_p, pose_t, pose_pos, pose_quat, settle_s: float = 0.5,
                    drift_tol_m: float = 0.5e-3, source: str = '') -> Recording:
    """Average the poses of every command step after ``settle_s`` (see the module doc).

    ``cmd_t`` (n,), ``cmd_p`` (n, A) in Pa; ``pose_t`` (m,), ``pose_pos`` (m, 3),
    ``pose_quat`` (m, 4, x y z w).  Raises :class:`RecordingError` when no
    step has settled poses.
    """
    cmd_t = np.asarray(cmd_t, dtype=float)
    cmd_p = np.asarray(cmd_p, dtype=float).reshape(len(cmd_t), -1)
    pose_t = np.asarray(pose_t, dtype=float)
    pose_pos = np.asarray(pose_pos, dtype=float).reshape(-1, 3)
    pose_quat = np.asarray(pose_quat, dtype=float).reshape(-1, 4)
    if not math.isfinite(settle_s) or settle_s < 0:
        raise RecordingError(f'settle time must be a non-negative number of seconds, '
                             f'got {settle_s}')
    order = np.argsort(cmd_t, kind='stable')
    cmd_t, cmd_p = cmd_t[order], cmd_p[order]
    order = np.argsort(pose_t, kind='stable')
    pose_t, pose_pos, pose_quat = pose_t[order], pose_pos[order], pose_quat[order]
    # steps: a command equal to the previous one continues the step
    starts = [0] + [k for k in range(1, len(cmd_t)) if not np.array_equal(cmd_p[k], cmd_p[k - 1])]
    ends = list(cmd_t[starts[1:]]) + [np.inf]
    out_p, out_x, out_q, out_t = [], [], [], []
    no_pose = drifting = nonfinite = outliers = 0
    for k, end in zip(starts, ends):
        if not np.all(np.isfinite(cmd_p[k])):
            nonfinite += 1
            continue
        t0 = cmd_t[k] + settle_s
        sel = np.flatnonzero((pose_t >= t0) & (pose_t < end))
        if sel.size:
            ok = (np.all(np.isfinite(pose_pos[sel]), axis=1)
                  & np.all(np.isfinite(pose_quat[sel]), axis=1))
            ok &= np.linalg.norm(pose_quat[sel], axis=1) > _MIN_QUAT_NORM
            sel = sel[ok]
        if sel.size >= 3:
            inlier = _not_spikes(pose_pos[sel])
            outliers += int(np.count_nonzero(~inlier))
            sel = sel[inlier]
        if sel.size == 0:
            no_pose += 1
            continue
        half = sel.size // 2
        if half >= 1:
            drift = np.linalg.norm(pose_pos[sel[half:]].mean(0) - pose_pos[sel[:half]].mean(0))
            if drift > drift_tol_m:
                drifting += 1
                continue
        q = pose_quat[sel] / np.linalg.norm(pose_quat[sel], axis=1)[:, None]
        out_p.append(cmd_p[k])
        out_x.append(pose_pos[sel].mean(axis=0))
        out_q.append(quaternion_mean(q))
        out_t.append(t0)
    notes = []
    if no_pose:
        notes.append(f'{no_pose} command step(s) without poses later than {settle_s:g} s '
                     f'after the change dropped')
    if drifting:
        notes.append(f'{drifting} command step(s) whose poses still moved by more than '
                     f'{drift_tol_m * 1e3:g} mm dropped (not settled)')
    if nonfinite:
        notes.append(f'{nonfinite} command(s) with NaN or inf pressures dropped')
    if outliers:
        notes.append(f'{outliers} pose(s) farther than {OUTLIER_M * 1e3:g} mm from the median '
                     'of the five around them dropped (outliers)')
    if not out_p:
        raise RecordingError(
            f'{source}: the poses never settle: none of the {len(starts)} command steps has '
            f'steady poses later than --settle-s {settle_s:g} s after its command change'
            + (f' ({"; ".join(notes)})' if notes else ''))
    return Recording(np.array(out_p), np.array(out_x), np.array(out_q), np.array(out_t),
                     source=source, notes=notes)


# ----------------------------------------------------------------- bags
def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def _find_topic(topics: dict, name: str, label: str, option: str) -> str:
    """The bag topic for ``name`` (exact, with a leading '/', or a unique namespaced match)."""
    if name in topics:
        return name
    if '/' + name.lstrip('/') in topics:
        return '/' + name.lstrip('/')
    tail = [t for t in topics if t.endswith('/' + name.lstrip('/'))]
    if len(tail) == 1:
        return tail[0]
    have = ', '.join(f'{t} ({topics[t]})' for t in sorted(topics)) or 'none'
    if len(tail) > 1:
        raise RecordingError(f'{label}: topic {name!r} is ambiguous ({", ".join(tail)}); '
                             f'give it in full with {option}')
    raise RecordingError(f'{label}: the bag has no topic {name!r} (topics: {have}); '
                         f'choose one with {option}')


def pressure_unit(msg, label: str) -> float:
    """Pascal per unit of a ``Float64MultiArray`` pressure message, from its layout label.

    ``..._kpa`` means kPa; ``..._pa`` or no label means Pa; any other label
    is refused (:class:`RecordingError` naming ``label``, where the message came from).
    """
    dims = list(getattr(msg.layout, 'dim', []) or [])
    lab = (dims[0].label if dims else '').strip().lower()
    if lab.endswith('_kpa') or lab == 'kpa':
        return _UNITS['kPa']
    if not lab or lab.endswith('_pa') or lab == 'pa':
        return _UNITS['Pa']
    raise RecordingError(f'{label}: pressure array label {dims[0].label!r} names no known unit '
                         f'(expected actuator_pressure_gauge_pa or actuator_pressure_gauge_kpa)')


def _bag_messages(path, wanted, handle) -> list:
    """Feed ``handle`` the messages of the ``wanted`` topics of a rosbag2 directory, in order.

    ``wanted``: ``(name, msgtype, option, required)`` per topic (``option``:
    the command-line option that chooses it, for the error); ``handle(i,
    topic, t_s, msg)`` gets each message of the ``i``-th with its receive
    time [s].  Returns the topics found (None: an optional one missing).  A
    missing directory, a missing or mistyped topic and a bag that cannot be
    read raise :class:`RecordingError` naming the bag.
    """
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    label = str(path)
    if not Path(path).exists():
        raise RecordingError(f'{label}: no such bag directory')
    store = _typestore()
    try:
        with Reader(path) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            found = []
            for name, want, option, required in wanted:
                try:
                    topic = _find_topic(topics, name, label, option)
                except RecordingError:
                    if required:
                        raise
                    topic = None
                if topic is not None and topics[topic] != want:
                    raise RecordingError(f'{label}: topic {topic} has type {topics[topic]}, '
                                         f'expected {want}')
                found.append(topic)
            index = {t: i for i, t in enumerate(found) if t is not None}
            conns = [c for c in reader.connections if c.topic in index]
            for conn, stamp, raw in reader.messages(connections=conns):
                handle(index[conn.topic], conn.topic, stamp * 1e-9,
                       store.deserialize_cdr(raw, conn.msgtype))
    except RecordingError:
        raise
    except (ReaderError, OSError, KeyError, ValueError, AssertionError) as exc:
        raise RecordingError(f'{label}: cannot read the bag: '
                             f'{type(exc).__name__}: {exc}') from None
    return found


def _pressures(msg, where: str, earlier: list) -> np.ndarray:
    """A pressure message's values [Pa], as many as the ``earlier`` ones (RecordingError)."""
    values = np.asarray(msg.data, dtype=float) * pressure_unit(msg, where)
    if earlier and values.size != earlier[0].size:
        raise RecordingError(f'{where}: {values.size} pressures, earlier messages had '
                             f'{earlier[0].size}')
    return values


def read_bag(path, pressure_topic: str = PRESSURE_TOPIC, pose_topic: str = POSE_TOPIC,
             settle_s: float = 0.5, n_actuators: int | None = None,
             drift_tol_m: float = 0.5e-3) -> Recording:
    """Read a rosbag2 directory (sqlite3 or mcap) into settled samples (module doc)."""
    label = str(path)
    cmd_t, cmd_p, pose_t, pose_x, pose_q = [], [], [], [], []
    frames = {}   # pose frame_id -> count

    def handle(i, topic, t, msg):
        if i == 0:
            where = f'{label}: {topic} message {len(cmd_t) + 1}'
            if n_actuators is not None and len(msg.data) != n_actuators:
                raise RecordingError(f'{where}: {len(msg.data)} pressures, the robot has '
                                     f'{n_actuators} actuators')
            cmd_t.append(t)
            cmd_p.append(_pressures(msg, where, cmd_p))
        else:
            p, o = msg.pose.position, msg.pose.orientation
            frames[msg.header.frame_id] = frames.get(msg.header.frame_id, 0) + 1
            pose_t.append(t)
            pose_x.append((p.x, p.y, p.z))
            pose_q.append((o.x, o.y, o.z, o.w))

    p_topic, x_topic = _bag_messages(
        path, [(pressure_topic, FLOAT64_MULTI_ARRAY, '--pressure-topic', True),
               (pose_topic, POSE_STAMPED, '--pose-topic', True)], handle)
    if not cmd_t:
        raise RecordingError(f'{label}: topic {p_topic} holds no messages')
    if not pose_t:
        raise RecordingError(f'{label}: topic {x_topic} holds no messages')
    rec = settled_samples(cmd_t, cmd_p, pose_t, pose_x, pose_q, settle_s, drift_tol_m, label)
    rec.frame_id = max(frames, key=frames.get)   # the poses' frame (the most frequent)
    if len(frames) > 1:
        rec.notes.append(f'poses in several frames {sorted(frames)}; taken as '
                         f'{rec.frame_id!r}')
    return rec


def write_bag(path, commands: Sequence, poses: Sequence, storage: str = 'sqlite3',
              pressure_topic: str = '/' + PRESSURE_TOPIC, pose_topic: str = '/' + POSE_TOPIC,
              unit: str = 'Pa', frame_id: str = 'mocap', measured: Sequence = (),
              measured_topic: str = '/' + MEASURED_PRESSURE_TOPIC) -> None:
    """Write a rosbag2 directory (``storage`` 'sqlite3' or 'mcap') without ROS.

    ``commands``: ``(t_s, pressures_pa)`` pairs; ``poses``: ``(t_s, position_m,
    quaternion_xyzw)`` triples (the pose header stamp is ``t_s`` too);
    ``measured``: ``(t_s, pressures_pa)`` pairs of the regulators' sensors, on
    ``measured_topic`` (none: no such topic).  Pressures are written in
    ``unit`` with the layout label the nodes use.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugins = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
    if storage not in plugins:
        raise ValueError(f'storage must be one of {sorted(plugins)}, got {storage!r}')
    if unit not in _UNITS:
        raise ValueError(f'unit must be one of {sorted(_UNITS)}, got {unit!r}')
    store = _typestore()
    T = store.types
    events = [(float(t), 0, np.asarray(p, dtype=float)) for t, p in commands]
    events += [(float(t), 1, (np.asarray(x, dtype=float), np.asarray(q, dtype=float)))
               for t, x, q in poses]
    events += [(float(t), 2, np.asarray(p, dtype=float)) for t, p in measured]
    events.sort(key=lambda e: (e[0], e[1]))
    with Writer(path, version=9, storage_plugin=plugins[storage]) as writer:
        c_cmd = writer.add_connection(pressure_topic, FLOAT64_MULTI_ARRAY, typestore=store)
        c_pose = writer.add_connection(pose_topic, POSE_STAMPED, typestore=store)
        c_meas = (writer.add_connection(measured_topic, FLOAT64_MULTI_ARRAY, typestore=store)
                  if len(measured) else None)
        for t, kind, value in events:
            ns = int(round(t * 1e9))
            if kind != 1:
                values = value / _UNITS[unit]
                dim = T['std_msgs/msg/MultiArrayDimension'](
                    label=f'actuator_pressure_gauge_{unit.lower()}', size=len(values),
                    stride=len(values))
                msg = T[FLOAT64_MULTI_ARRAY](
                    layout=T['std_msgs/msg/MultiArrayLayout'](dim=[dim], data_offset=0),
                    data=values.astype(np.float64))
                writer.write(c_cmd if kind == 0 else c_meas, ns,
                             store.serialize_cdr(msg, FLOAT64_MULTI_ARRAY))
            else:
                x, q = value
                stamp = T['builtin_interfaces/msg/Time'](sec=ns // 1_000_000_000,
                                                         nanosec=ns % 1_000_000_000)
                msg = T[POSE_STAMPED](
                    header=T['std_msgs/msg/Header'](stamp=stamp, frame_id=frame_id),
                    pose=T['geometry_msgs/msg/Pose'](
                        position=T['geometry_msgs/msg/Point'](x=x[0], y=x[1], z=x[2]),
                        orientation=T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2],
                                                                      w=q[3])))
                writer.write(c_pose, ns, store.serialize_cdr(msg, POSE_STAMPED))


class BagWriter:
    """A rosbag2 directory written without ROS (``rosbags``): topics and serialized messages.

    ``topic(name, msgtype)`` adds a topic of a ROS 2 Jazzy message type
    (``'geometry_msgs/msg/PoseStamped'``); ``write(name, t_ns, cdr)`` appends
    a message already serialized (CDR, as rclpy delivers it with ``raw=True``).
    Use as a context manager; ``storage``: ``'sqlite3'`` or ``'mcap'``.
    """

    def __init__(self, path, storage: str = 'sqlite3') -> None:
        """Open ``path`` (must not exist) for writing."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugins = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
        if storage not in plugins:
            raise ValueError(f'storage must be one of {sorted(plugins)}, got {storage!r}')
        self._store = _typestore()
        self._writer = Writer(path, version=9, storage_plugin=plugins[storage])
        self._connections = {}
        self.counts = {}

    def __enter__(self) -> 'BagWriter':
        self._writer.open()
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()

    def topic(self, name: str, msgtype: str) -> None:
        """Add topic ``name`` of ``msgtype``; an unknown type raises ValueError naming it."""
        if msgtype not in self._store.types:
            raise ValueError(f'{name}: message type {msgtype!r} is not a ROS 2 Jazzy type '
                             'rosbags knows')
        self._connections[name] = self._writer.add_connection(name, msgtype,
                                                              typestore=self._store)
        self.counts[name] = 0

    def write(self, name: str, t_ns: int, cdr: bytes) -> None:
        """Append one serialized message of topic ``name`` at time ``t_ns`` [ns]."""
        self._writer.write(self._connections[name], int(t_ns), bytes(cdr))
        self.counts[name] += 1


def read_recording(csv_path=None, bag_path=None, n_actuators: int | None = None,
                   **bag_options) -> Recording:
    """Read a CSV file or a bag directory (exactly one of the two)."""
    if (csv_path is None) == (bag_path is None):
        raise RecordingError('give exactly one of a CSV file and a bag directory')
    if csv_path is not None:
        return read_csv(csv_path, n_actuators)
    return read_bag(bag_path, n_actuators=n_actuators, **bag_options)


# ------------------------------------------------------------ pose streams
#: The columns a pose-stream CSV file must have (module doc).
POSE_STREAM_COLUMNS = ('t_s', 'x_m', 'y_m', 'z_m')


@dataclass
class PoseStream:
    """Raw end-effector positions over time and the pressures in effect (SI units).

    ``times_s`` (n,), ``positions_m`` (n, 3), sorted by time;
    ``pressure_times_s`` (m,) and ``pressures_pa`` (m, A): the pressure
    inputs (empty when the recording has none); ``frame_id`` as in
    :class:`Recording`.
    """

    times_s: np.ndarray
    positions_m: np.ndarray
    pressure_times_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pressures_pa: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    source: str = ''
    frame_id: str = ''
    notes: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.times_s = np.asarray(self.times_s, dtype=float).ravel()
        self.positions_m = np.asarray(self.positions_m, dtype=float).reshape(-1, 3)
        order = np.argsort(self.times_s, kind='stable')
        self.times_s, self.positions_m = self.times_s[order], self.positions_m[order]
        self.pressure_times_s = np.asarray(self.pressure_times_s, dtype=float).ravel()
        p = np.asarray(self.pressures_pa, dtype=float)
        self.pressures_pa = p.reshape(len(self.pressure_times_s), -1) if p.size else \
            np.zeros((len(self.pressure_times_s), 0))
        order = np.argsort(self.pressure_times_s, kind='stable')
        self.pressure_times_s = self.pressure_times_s[order]
        self.pressures_pa = self.pressures_pa[order]

    def __len__(self) -> int:
        return len(self.times_s)

    @property
    def has_pressures(self) -> bool:
        """Whether the recording holds pressures."""
        return len(self.pressure_times_s) > 0

    def pressures_at(self, t_s: float):
        """The pressures [Pa] in effect at ``t_s`` (the last input at or before it), or None."""
        if not self.has_pressures:
            return None
        k = int(np.searchsorted(self.pressure_times_s, t_s, side='right')) - 1
        return self.pressures_pa[max(k, 0)].copy()


def read_pose_stream_csv(path) -> PoseStream:
    """Read a pose-stream CSV file (module doc: ``t_s, x_m, y_m, z_m [, p1_kpa ...]``)."""
    label = str(path)

    def check(header, line):
        missing = [c for c in POSE_STREAM_COLUMNS if c not in header]
        if missing:
            raise RecordingError(
                f'{label}, line {line}: no column {missing[0]} (expected '
                f'{",".join(POSE_STREAM_COLUMNS)}[,p1_kpa,...]; got {",".join(header)})')

    header, records = numeric_csv_rows(path, check)
    rows = [values for _, values in records]
    if header is None:
        raise RecordingError(f'{label}: the file is empty (expected the header '
                             f'{",".join(POSE_STREAM_COLUMNS)})')
    if not rows:
        raise RecordingError(f'{label}: no data rows after the header')
    data = np.array(rows)
    col = {name: i for i, name in enumerate(header)}
    t = data[:, col['t_s']]
    x = data[:, [col['x_m'], col['y_m'], col['z_m']]]
    n_p = 0
    while f'p{n_p + 1}_kpa' in col:
        n_p += 1
    p = data[:, [col[f'p{i + 1}_kpa'] for i in range(n_p)]] * 1e3
    keep = np.isfinite(t) & np.all(np.isfinite(x), axis=1)
    notes = []
    if not np.all(keep):
        notes.append(f'{int(np.count_nonzero(~keep))} row(s) with NaN or inf dropped')
    if n_p:
        keep_p = keep & np.all(np.isfinite(p), axis=1)
        return PoseStream(t[keep], x[keep], t[keep_p], p[keep_p], source=label, notes=notes)
    return PoseStream(t[keep], x[keep], source=label, notes=notes)


def read_pose_stream_bag(path, pose_topic: str = POSE_TOPIC,
                         pressure_topic: str = PRESSURE_TOPIC) -> PoseStream:
    """Read every pose (and pressure command, if any) of a rosbag2 directory (module doc)."""
    label = str(path)
    recv, stamps, pos, cmd_t, cmd_p = [], [], [], [], []
    frames = {}

    def handle(i, topic, t, msg):
        if i == 0:
            p = msg.pose.position
            recv.append(t)
            stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            pos.append((p.x, p.y, p.z))
            frames[msg.header.frame_id] = frames.get(msg.header.frame_id, 0) + 1
        else:
            cmd_t.append(t)
            cmd_p.append(_pressures(msg, f'{label}: {topic} message {len(cmd_t)}', cmd_p))

    x_topic, p_topic = _bag_messages(
        path, [(pose_topic, POSE_STAMPED, '--pose-topic', True),
               (pressure_topic, FLOAT64_MULTI_ARRAY, '--pressure-topic', False)], handle)
    notes = [] if p_topic is not None else [f'no {pressure_topic} topic: no recorded pressures']
    if not pos:
        raise RecordingError(f'{label}: topic {x_topic} holds no messages')
    stamps = np.array(stamps)
    times = stamps if np.all(stamps > 0) else np.array(recv)
    if times is not stamps:
        notes.append('poses without header stamps: the receive times are used')
    frame = max(frames, key=frames.get)
    if p_topic is not None and not cmd_t:
        notes.append(f'topic {p_topic} holds no messages: no recorded pressures')
    if cmd_t:
        # the commands' receive times, on the poses' clock
        shift = float(np.median(stamps - np.array(recv))) if times is stamps else 0.0
        cmd_t = np.array(cmd_t) + shift
    return PoseStream(times, np.array(pos), np.asarray(cmd_t, dtype=float),
                      np.array(cmd_p) if cmd_p else np.zeros((0, 0)), source=label,
                      frame_id=frame, notes=notes)


def read_pose_stream(csv_path=None, bag_path=None, **bag_options) -> PoseStream:
    """Read a pose stream from a CSV file or a bag directory (exactly one of the two)."""
    if (csv_path is None) == (bag_path is None):
        raise RecordingError('give exactly one of a CSV file and a bag directory')
    if csv_path is not None:
        return read_pose_stream_csv(csv_path)
    return read_pose_stream_bag(bag_path, **bag_options)


# ------------------------------------------------------- pressure recordings


@dataclass
class PressureRecording:
    """The regulators' measured pressures and the set-points in effect (module doc).

    ``times_s`` (n,) increasing; ``command_pa`` and ``measured_pa`` (n, A) [Pa].
    """

    times_s: np.ndarray
    command_pa: np.ndarray
    measured_pa: np.ndarray
    source: str = ''

    def __len__(self) -> int:
        """The number of measured samples."""
        return len(self.times_s)


def pressure_csv_header(n_actuators: int) -> list[str]:
    """``t_s, p1_kpa, ..., pN_kpa, m1_kpa, ..., mN_kpa``."""
    return (['t_s'] + [f'p{i + 1}_kpa' for i in range(n_actuators)]
            + [f'm{i + 1}_kpa' for i in range(n_actuators)])


def _pressure_recording(t, cmd, meas, label: str) -> PressureRecording:
    t, cmd, meas = np.asarray(t, float), np.asarray(cmd, float), np.asarray(meas, float)
    if len(t) < 3:
        raise RecordingError(f'{label}: {len(t)} measured samples with a set-point in effect; '
                             'at least 3 needed')
    if not (np.all(np.isfinite(cmd)) and np.all(np.isfinite(meas))):
        raise RecordingError(f'{label}: a pressure is not finite (NaN or inf)')
    order = np.argsort(t, kind='stable')
    return PressureRecording(t[order], cmd[order], meas[order], source=label)


def _read_pressure_csv(path) -> PressureRecording:
    label = str(path)

    def check(header, line):
        n = (len(header) - 1) // 2
        if n < 1 or header != pressure_csv_header(n):
            raise RecordingError(f'{label}, line {line}: expected the header '
                                 f'{",".join(pressure_csv_header(max(n, 1)))}, got '
                                 f'{",".join(header)}')
    header, rows = numeric_csv_rows(path, check)
    if header is None:
        raise RecordingError(f'{label}: the file is empty (expected the header '
                             f'{",".join(pressure_csv_header(3))})')
    data = np.array([v for _, v in rows]).reshape(-1, len(header))
    n = (len(header) - 1) // 2
    return _pressure_recording(data[:, 0], data[:, 1:1 + n] * 1e3, data[:, 1 + n:] * 1e3, label)


def _read_pressure_bag(path, command_topic: str, measured_topic: str) -> PressureRecording:
    label = str(path)
    got = (([], []), ([], []))   # (times, values) of the set-points and the measured pressures

    def handle(i, topic, t, msg):
        times, values = got[i]
        values.append(_pressures(msg, f'{label}: {topic} message {len(times) + 1}', values))
        times.append(t)

    _bag_messages(path, [(command_topic, FLOAT64_MULTI_ARRAY, '--pressure-topic', True),
                         (measured_topic, FLOAT64_MULTI_ARRAY, '--measured-topic', True)],
                  handle)
    (tc, pc), (tm, pm) = got
    if pc and pm and pc[0].size != pm[0].size:
        raise RecordingError(f'{label}: {pc[0].size} set-points but {pm[0].size} measured '
                             'pressures per message')
    tc, tm = np.array(tc), np.array(tm)
    k = np.searchsorted(tc, tm, side='right') - 1   # the newest set-point received before
    keep = k >= 0
    return _pressure_recording(tm[keep], np.array(pc)[k[keep]] if len(pc) else np.zeros((0, 1)),
                               np.array(pm)[keep] if len(pm) else np.zeros((0, 1)), label)


def read_pressure_recording(csv_path=None, bag_path=None,
                            command_topic: str = PRESSURE_TOPIC,
                            measured_topic: str = MEASURED_PRESSURE_TOPIC) -> PressureRecording:
    """Read a pressure recording from a CSV file or a bag directory (exactly one)."""
    if (csv_path is None) == (bag_path is None):
        raise RecordingError('give exactly one of a CSV file and a bag directory')
    if csv_path is not None:
        return _read_pressure_csv(csv_path)
    return _read_pressure_bag(bag_path, command_topic, measured_topic)
