"""``bellow-ancf record``: a rosbag2 recorder for machines without rosbag2 (through rosbags).

Registered by :func:`register` into the parser of :mod:`bellow_ancf_ros.cli`::

    bellow-ancf record --out DIR [--topics T ...] [--duration S] [--storage sqlite3|mcap]
                       [--use-sim-time]

``ros2 bag`` is not on PyPI; this records the topics ``bellow-ancf
calibrate`` reads (default ``/pressure_command`` and ``/measured_pose``)
into a rosbag2 directory with the ``rosbags`` writer
(:class:`~bellow_ancf_ros.core.fit.BagWriter`), messages as the middleware
delivers them (CDR) with their reception time.  Each topic's type comes from
the ROS graph (the command waits up to ``--wait-s`` for a publisher); a
best-effort subscription, so that reliable and best-effort publishers (a
mocap driver) are both recorded.  Stops after ``--duration`` seconds or on
Ctrl-C, then prints how many messages each topic got.  Needs rclpy (a ROS
install, or this repository's venv); the ROS domain is the environment's.

``--use-sim-time`` (as ``ros2 bag record --use-sim-time``): the reception
times are the ``/clock``'s (a simulated robot that is the clock, or a bag
played back with ``--clock``), so that they match the simulation-time stamps
of the poses; recording starts with the first ``/clock``.  ``--duration``
stays wall seconds.
"""

from __future__ import annotations

import importlib
import os
import signal
import time

from .common import EXIT_OK, UsageError

__all__ = ['register']


def _message_class(msgtype: str):
    pkg, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


def _cmd_record(args) -> int:
    if os.path.exists(args.out):
        raise UsageError(f'--out {args.out}: exists already (a bag directory must be new)')
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from ..core.fit import BagWriter

    topics = [t if t.startswith('/') else '/' + t for t in args.topics]
    from rclpy.parameter import Parameter

    rclpy.init(args=[])
    node = rclpy.create_node('bellow_ancf_recorder', parameter_overrides=[
        Parameter('use_sim_time', value=bool(args.use_sim_time))])
    clock = node.get_clock()
    stop = {'now': False}

    def on_signal(signum, frame):
        stop['now'] = True
    old = signal.signal(signal.SIGINT, on_signal)
    try:
        types, deadline = {}, time.monotonic() + args.wait_s
        while len(types) < len(topics) and time.monotonic() < deadline and not stop['now']:
            rclpy.spin_once(node, timeout_sec=0.1)
            for name, ts in node.get_topic_names_and_types():
                if name in topics and ts:
                    types[name] = ts[0]
        while (args.use_sim_time and clock.now().nanoseconds == 0 and not stop['now']
               and time.monotonic() < deadline):
            rclpy.spin_once(node, timeout_sec=0.1)
        if args.use_sim_time and clock.now().nanoseconds == 0 and not stop['now']:
            raise UsageError(f'--use-sim-time: no /clock seen within {args.wait_s:g} s (is the '
                             f'simulation publishing it, or the bag played with --clock?)')
        missing = [t for t in topics if t not in types]
        if missing:
            raise UsageError(f'--topics: no publisher of {", ".join(missing)} seen within '
                             f'{args.wait_s:g} s (is the ROS domain right?)')
        qos = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                         history=HistoryPolicy.KEEP_LAST, depth=1000)

        def stamp_now() -> int:   # the reception time: /clock's, or the system clock's
            return clock.now().nanoseconds if args.use_sim_time else time.time_ns()

        with BagWriter(args.out, args.storage) as bag:
            for name in topics:
                try:
                    bag.topic(name, types[name])
                except ValueError as exc:
                    raise UsageError(f'--topics: {exc}') from None
                node.create_subscription(
                    _message_class(types[name]), name,
                    lambda raw, name=name: bag.write(name, stamp_now(), raw), qos, raw=True)
            print(f'recording {", ".join(topics)} to {args.out} ({args.storage})'
                  + (f' for {args.duration:g} s' if args.duration else '; Ctrl-C stops'),
                  flush=True)
            end = time.monotonic() + args.duration if args.duration else None
            while not stop['now'] and (end is None or time.monotonic() < end):
                rclpy.spin_once(node, timeout_sec=0.05)
            counts = dict(bag.counts)
    finally:
        signal.signal(signal.SIGINT, old)
        node.destroy_node()
        rclpy.try_shutdown()
    print('recorded: ' + ', '.join(f'{t} {n} messages' for t, n in counts.items()), flush=True)
    return EXIT_OK


def register(subparsers) -> None:
    """Add the ``record`` subcommand."""
    p = subparsers.add_parser(
        'record', help='record topics to a rosbag2 directory without rosbag2 (rosbags)',
        description='Record topics (default the ones bellow-ancf calibrate reads) into a '
                    'rosbag2 directory, sqlite3 or mcap, without ros2 bag.',
        epilog='Example: bellow-ancf record --out my_robot_bag --duration 600')
    p.add_argument('--out', required=True, metavar='DIR', help='new bag directory')
    p.add_argument('--topics', nargs='+', default=['/pressure_command', '/measured_pose'],
                   metavar='T', help='topics; default: %(default)s')
    p.add_argument('--duration', type=float, default=0.0, metavar='S',
                   help='seconds to record; default: until Ctrl-C')
    p.add_argument('--storage', choices=('sqlite3', 'mcap'), default='sqlite3',
                   help='bag storage; default: %(default)s')
    p.add_argument('--wait-s', type=float, default=10.0, metavar='S',
                   help='wait this long for a publisher of every topic; default: %(default)s')
    p.add_argument('--use-sim-time', action='store_true',
                   help='reception times from /clock (a simulation, or a bag played with '
                        '--clock), as ros2 bag record --use-sim-time')
    p.set_defaults(func=_cmd_record)
