"""Run node processes and record their topics: the machinery of the ROS demos.

Used by :mod:`bellow_ancf_ros.demos.closed_loop` (the main job) and
:mod:`bellow_ancf_ros.demos.wiring_check`.  Every node runs as a separate
process (``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``) in its
own session, on an isolated ``ROS_DOMAIN_ID`` with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; :class:`Recorder` subscribes in
this process with rclpy and stores every message with its arrival time.

Simulation time (the main job's default): the simulated robot is the
clock (``publish_clock``, in ``lockstep`` with the controller's commands,
:func:`clock_parameters`), every node and the recorder run on it
(``use_sim_time``), and the demos' phases are measured on it
(:meth:`SpunNode.now`, :meth:`SpunNode.wait_for`).
"""

from __future__ import annotations

from datetime import datetime, timezone
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable

__all__ = ['NodeProcess', 'Recorder', 'SimulationStalled', 'TargetSender', 'child_env',
           'clock_parameters', 'group_nice', 'hardware_parameters', 'machine_state',
           'message_time', 'plant_effects', 'start_clock', 'stop_all', 'tidy', 'wait_until',
           'wait_up']

#: Wall seconds without the simulation's clock moving before a wait gives up.
STALL_S = 30.0
#: How long a recorder is given to take the controller's vent once the controller exited [s].
VENT_SEEN_S = 5.0


class SimulationStalled(RuntimeError):
    """The simulation's clock did not move for :data:`STALL_S` wall seconds."""


def clock_parameters(sim_time: bool, robot: bool = False, real_time_factor: float = 1.0) -> dict:
    """The parameters that put a node on simulation time (``robot``: the one that is the clock).

    The simulated robot publishes ``/clock`` in lockstep with the
    controller's commands, paced at ``real_time_factor`` (0: as fast as the
    controller's reports allow), and starts paused (:func:`start_clock`);
    every node uses it.  Its lockstep waits up to 5 s (wall) for a report
    or a message owed: a demo holds it while a node process exits.  Nothing
    without ``sim_time`` (the wall clock).
    """
    if not sim_time:
        return {}
    return dict({'use_sim_time': True},
                **({'publish_clock': True, 'lockstep': True, 'start_paused': True,
                    'lockstep_timeout_s': 5.0,
                    'real_time_factor': float(real_time_factor)} if robot else {}))


def start_clock(rec: 'SpunNode', procs, ready, clock_users: int, timeout: float) -> None:
    """Simulation time: once every node is up, unpause the simulated robot (it starts paused).

    Waits until ``ready()`` and ``clock_users`` nodes (the recorder and the
    simulated robot among them) subscribe ``/clock``, so that every node
    sees the first step and the runs start from the same state at the same
    time whatever the machine's load.  Raises when they do not come up.
    """
    if not wait_up(procs, lambda: ready() and rec.node.count_subscribers('/clock') >= clock_users,
                   timeout):
        raise RuntimeError('nodes did not come up')
    try:
        rec.trigger('/simulated_robot_node/unpause')
    except RuntimeError:
        # unpaused all the same when its clock moves: the middleware can lose a service's
        # answer to a client it has not matched yet ("failed to send response (timeout)")
        if not wait_until(lambda: rec.now() > 0.0, 2.0):
            raise


def group_nice(pid: int, nice: int) -> bool:
    """Give the session of ``pid`` (its autogroup) the niceness ``nice``; whether it took.

    With the kernel's autogroups (``/proc/sys/kernel/sched_autogroup_enabled``)
    every session is one scheduling group and a process's own niceness
    counts only inside it: a node in a session of its own, as here, beside
    CPU-bound processes in sessions of theirs would get the same share
    whatever its ``nice -n``.  False without autogroups or the privilege.
    """
    try:
        Path(f'/proc/{pid}/autogroup').write_text(f'{int(nice)}\n')
    except OSError:
        return False
    return True


class NodeProcess:
    """One node as a child process (``params``: name -> value, ``remaps``: from -> to)."""

    def __init__(self, module: str, params: dict, env: dict, log_dir: Path,
                 remaps: dict | None = None, tag: str = '', nice: int = 0) -> None:
        """Start ``python -m bellow_ancf_ros.nodes.<module>``; its log goes to ``log_dir``.

        ``nice``: run it that much nicer (``nice -n``; negative: above this
        process, which needs the privilege to), its session's scheduling
        group too (:func:`group_nice`).
        """
        self.module = module
        self.nice = int(nice)
        self._interrupted = False
        self.log_path = log_dir / f'{tag}{module}.log'
        self.cmd = ((['nice', '-n', str(int(nice))] if nice else [])
                    + [sys.executable, '-m', f'bellow_ancf_ros.nodes.{module}', '--ros-args'])
        for k, v in params.items():
            self.cmd += ['-p', f'{k}:={v}']
        for k, v in (remaps or {}).items():
            self.cmd += ['-r', f'{k}:={v}']
        self.env = env
        self._start('w')

    def _start(self, mode: str) -> None:
        with open(self.log_path, mode) as log:
            self.proc = subprocess.Popen(self.cmd, env=self.env, stdout=log,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         start_new_session=True)
        if self.nice:
            group_nice(self.proc.pid, self.nice)
        self._interrupted = False

    def silent(self) -> bool:
        """True while the process runs and has written nothing to its log yet."""
        try:
            return self.alive() and self.log_path.stat().st_size == 0
        except OSError:
            return False

    def dump_stacks(self, wait_s: float = 1.0) -> str:
        """Have the process print its threads' Python stacks into its log (SIGUSR1); where.

        The nodes register :mod:`faulthandler` on SIGUSR1, which answers even
        while the main thread is stuck inside a C call.
        """
        if self.alive():
            try:
                os.kill(self.proc.pid, signal.SIGUSR1)
            except ProcessLookupError:
                pass
            time.sleep(wait_s)
        return str(self.log_path)

    def restart_if_silent(self) -> bool:
        """A process that hung before its first output: stacks to its log, kill, start again.

        Returns True when it restarted it.  Its log keeps the hung run (with
        its stacks) above the new one.
        """
        if not self.silent():
            return False
        self.dump_stacks()
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(5.0)
        stacks = self.log_path.read_text()
        print(f'  {self.module} hung before its first output; its stacks:\n{stacks}'
              f'  {self.module} restarted once')
        with open(self.log_path, 'a') as log:
            log.write('--- restarted after a hang at start-up ---\n')
        self._start('a')
        return True

    def alive(self) -> bool:
        """True while the process runs."""
        return self.proc.poll() is None

    def interrupt(self) -> None:
        """SIGINT to the process group (Ctrl-C) once, without waiting."""
        if self.proc.poll() is None and not self._interrupted:
            self._interrupted = True
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
            except ProcessLookupError:
                pass

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGINT to the process group, wait, then SIGKILL; returns the exit code."""
        if self.proc.poll() is None:
            self.interrupt()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                print(f'  {self.module} did not stop on SIGINT within {timeout:g} s: SIGKILL '
                      f'(its stacks: {self.dump_stacks()})')
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.proc.wait(5.0)
        return self.proc.returncode

    def tail(self, n: int = 15) -> str:
        """The last ``n`` lines of the node's log."""
        try:
            return '\n'.join(self.log_path.read_text().splitlines()[-n:])
        except OSError:
            return ''


def child_env(domain: int) -> dict:
    """Environment of the node processes: domain, localhost discovery, this package first."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    # the package as imported here (source checkout or install) for the children too
    pkg_parent = str(Path(__file__).resolve().parents[2])   # (the directory holding it)
    env['PYTHONPATH'] = pkg_parent + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH')
                                      else '')
    return env


def plant_effects(plant: str):
    """The simulated robot's effects for its ``plant`` parameter (``realistic`` or ``ideal``)."""
    from ..core.sim import PlantEffects
    return PlantEffects() if plant == 'realistic' else PlantEffects.ideal()


def machine_state() -> dict:
    """The time (UTC, ISO 8601) and the machine's load average (1, 5, 15 min; None: unknown).

    What a run's results file records at its start and end (the demos, the benches).
    """
    try:
        load = [round(v, 2) for v in os.getloadavg()]
    except OSError:       # not on every platform
        load = None
    return {'date': datetime.now(timezone.utc).isoformat(timespec='seconds'), 'load': load}


def hardware_parameters(plant: str) -> dict:
    """What the inverse node is told of the simulated plant's hardware, as a lab tells it.

    The regulators' play (``regulator_play_kpa``: a lab takes it from their
    data sheet) and the bellows' creep (``creep_fraction``,
    ``creep_time_constant_s``: a lab identifies them from a recorded pressure
    step, ``bellow-ancf identify creep``); with both compensated, the
    correction the closed loop holds is the robot's static mismatch, which
    ``feedback_correction_frame: model`` carries to a jump's goal.
    """
    e = plant_effects(plant)
    return {'regulator_play_kpa': e.regulator_hysteresis_pa / 1e3,
            'creep_fraction': e.creep_fraction,
            'creep_time_constant_s': e.creep_time_constant_s,
            'feedback_correction_frame': 'model'}


def record_qos():
    """Record everything: a deep reliable queue, so that a busy recorder loses nothing."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=1000)


class SpunNode:
    """rclpy in this process: a node in its own context on ``domain``, spun in a thread.

    Subclasses create their publishers and subscriptions on ``self.node``,
    then call :meth:`start`; ``self.lock`` guards what callbacks store.
    """

    def __init__(self, domain: int, name: str, sim_time: bool = False) -> None:
        """Own context and node (``sim_time``: on ``/clock``); not spinning until :meth:`start`."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter

        self.rclpy = rclpy
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node(name, context=self.ctx, parameter_overrides=[
            Parameter('use_sim_time', value=bool(sim_time))])
        self.lock = threading.Lock()
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self._closed = threading.Event()
        self.spin_errors = 0   #: waits that raised (an entity destroyed meanwhile); spun on
        self.thread = threading.Thread(target=self._spin, daemon=True)

    def start(self) -> None:
        """Spin the node in its thread."""
        self.thread.start()

    def now(self) -> float:
        """The node's time [s]: simulation time on ``/clock``, else the monotonic clock."""
        from ..nodes.ros_util import control_now
        return control_now(self.node)

    def wait_for(self, until: float, check=None) -> None:
        """Wait until :meth:`now` reaches ``until``, calling ``check()`` every 10 ms.

        Raises :class:`SimulationStalled` when the clock did not move for
        :data:`STALL_S` wall seconds (a simulation that stopped).
        """
        last, moved = self.now(), time.monotonic()
        while (now := self.now()) < until:
            if check is not None:
                check()
            if now != last:
                last, moved = now, time.monotonic()
            elif time.monotonic() - moved > STALL_S:
                raise SimulationStalled(f'the clock stood at {now:.3f} s for {STALL_S:g} s')
            time.sleep(0.01)

    def trigger(self, service: str, timeout: float = 10.0) -> None:
        """Call the std_srvs/Trigger ``service`` (the robot's unpause...); raise if refused."""
        from std_srvs.srv import Trigger
        cli = self.node.create_client(Trigger, service)
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                raise RuntimeError(f'no service {service}')
            future = cli.call_async(Trigger.Request())
            if not wait_until(future.done, timeout):
                raise RuntimeError(f'{service} did not answer in {timeout:g} s')
            if not future.result().success:
                raise RuntimeError(f'{service} refused: {future.result().message}')
        finally:
            self.node.destroy_client(cli)

    def _spin(self) -> None:
        """Spin until :meth:`close`; a wait that raises is counted in :attr:`spin_errors`.

        (:func:`~..nodes.ros_util.spin_until_closed`: an entity the demo
        destroyed as a closed-loop run ended made rclpy's wait raise, and
        ``executor.spin()`` ended there; the recorder then missed the vent,
        acknowledged by its middleware, in 5 of 18 short runs beside two
        CPU-bound processes, 0 of 20 with the spin going on.  From
        :meth:`wait_for` the same death looks like a clock that stands
        still, as one CI run's loads phase reported: not reproduced, a
        likely cause.)
        """
        from ..nodes.ros_util import spin_until_closed

        def count(_exc) -> None:
            self.spin_errors += 1
        spin_until_closed(self.executor, self.ctx, self._closed, count)

    def close(self) -> None:
        """Stop spinning and shut the context down."""
        self._closed.set()
        self.executor.shutdown(timeout_sec=2.0)
        if self.thread.is_alive():
            self.thread.join(5.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


class Recorder(SpunNode):
    """rclpy in this process: records ``topics`` (name -> message type) with arrival times."""

    def __init__(self, domain: int, topics: dict, name: str = 'ros_demo_recorder',
                 sim_time: bool = False) -> None:
        """Own context on ``domain``, one subscription per topic, spun in a thread.

        Arrival times on :meth:`now` (simulation time with ``sim_time``).
        """
        super().__init__(domain, name, sim_time)
        qos = record_qos()
        self.msgs = {t: [] for t in topics}
        self.subs = {}
        for topic, typ in topics.items():
            self.subs[topic] = self.node.create_subscription(
                typ, topic, lambda m, topic=topic: self._store(topic, m), qos)
        self.start()

    def _store(self, topic: str, msg) -> None:
        with self.lock:
            self.msgs[topic].append((self.now(), msg))

    def publishers(self, topic: str) -> int:
        """Number of publishers matched on ``topic``."""
        return self.subs[topic].get_publisher_count()

    def count(self, topic: str) -> int:
        """Messages recorded on ``topic`` so far."""
        with self.lock:
            return len(self.msgs[topic])

    def wait_for_vent(self, topic: str = 'pressure_command', timeout: float = VENT_SEEN_S) -> bool:
        """Wait until the newest message on ``topic`` is the vent (every pressure 0 Pa gauge).

        The controller's vent is acknowledged by this process's middleware
        before the controller exits, but the callback that records it runs on
        this process's executor thread, which a busy machine delays.  A
        fresh-clone ``make test`` beside two CPU-bound processes recorded no
        vent in 2 of 3 short runs (not reproduced in 5 more); whether the
        callback was late or the sample never came is not established, and a
        late callback is given ``timeout``.  True when seen in time.
        """
        def seen():
            with self.lock:
                got = self.msgs.get(topic)
                return bool(got) and not any(float(v) != 0.0 for v in got[-1][1].data)
        return wait_until(seen, timeout)

    def snapshot(self) -> dict:
        """A copy of everything recorded: topic -> [(arrival time (:meth:`now`), message), ...]."""
        with self.lock:
            return {k: list(v) for k, v in self.msgs.items()}

    def clear(self) -> None:
        """Forget everything recorded so far."""
        with self.lock:
            for v in self.msgs.values():
                v.clear()


#: A hold at a time reports done until this long before it [s] (more than the simulation
#: clock's 1 ns tolerance, less than any physics step).
HOLD_BEFORE_S = 1e-6


class TargetSender:
    """A demo's own ``target_pose`` publisher, in the simulation's lockstep on simulation time.

    Each target it sends is counted in its lockstep report (the simulated
    robot takes no step until the inverse node has it), and it may hold the
    simulation at a time (:meth:`hold`): there the demo acts (a step target,
    the hand-over from the trajectory publisher) at the same simulated time in
    every run, however long the computer takes.  On the wall clock it only
    publishes.
    """

    def __init__(self, node) -> None:
        from geometry_msgs.msg import PoseStamped

        from ..nodes.lockstep import LockstepReport
        from ..nodes.ros_util import command_qos
        self.node = node
        self.pub = node.create_publisher(PoseStamped, 'target_pose', command_qos())
        self._lockstep = LockstepReport(node, follow_clock=False)
        self._hold_at: float | None = None

    def inverse_matched(self) -> bool:
        """The inverse node subscribes and every subscriber is matched.

        A target sent before its reader matched never arrives: the lockstep
        would wait for it until its timeout.
        """
        subs = self.node.get_subscriptions_info_by_topic(self.pub.topic_name)
        return (any(i.node_name == 'inverse_kinetostatic_node' for i in subs)
                and self.pub.get_subscription_count() >= len(subs))

    def send(self, msg) -> None:
        """Publish a target and count it."""
        self._lockstep.publish(self.pub, msg)
        self._report()

    def hold(self, t: float | None) -> None:
        """Hold the simulation at simulated time ``t`` [s] (None: let it run).

        It runs up to ``t`` and takes no step from there until the demo has
        acted (sent, or held elsewhere): the report says done until just
        before ``t`` (:data:`HOLD_BEFORE_S`).  A report of ``t`` itself let
        the robot step past ``t`` before a target sent at ``t`` reached the
        inverse node, in some runs and not in others: the ZVD-shaped step's
        first level went out one physics step late, and its residual swing
        was 0.163 mm instead of 0.044 (2 runs in 15).
        """
        self._hold_at = t
        self._report()

    def _report(self) -> None:
        if self._hold_at is None:
            self._lockstep.report_counts()
        else:
            self._lockstep.report(self._hold_at - HOLD_BEFORE_S)

    def every(self, period_s: float, fn: Callable[[], None]) -> Callable[[], None]:
        """Call ``fn`` every ``period_s`` of the node's clock from now; returns a cancel.

        On simulation time at the first clock update at or after each tick
        (rcl's timers on ``/clock`` can fire twice at one time and skip the
        next tick), and the simulation is held just before the next tick until
        ``fn`` has run: its targets reach the inverse node at the same
        simulated times in every run, however late the computer runs it.  On
        the wall clock an ordinary timer.
        """
        from rclpy.clock import JumpThreshold
        from rclpy.duration import Duration
        node = self.node
        if not self._lockstep.active:
            timer = node.create_timer(period_s, fn)
            return timer.cancel
        clock, period = node.get_clock(), int(round(period_s * 1e9))
        lock, state = threading.Lock(), {'due': clock.now().nanoseconds + period, 'on': True}
        self.hold(state['due'] * 1e-9)

        def on_time(_jump) -> None:
            with lock:
                now = clock.now().nanoseconds
                if not state['on'] or now < state['due']:
                    return
                state['due'] += period * (1 + (now - state['due']) // period)
            fn()
            with lock:
                if state['on']:
                    self.hold(state['due'] * 1e-9)
        handle = clock.create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1),
                          min_backward=Duration(nanoseconds=-1), on_clock_change=False),
            post_callback=on_time)

        def cancel() -> None:   # (the hold stays where it is)
            with lock:
                state['on'] = False
            handle.unregister()
        return cancel

    def close(self) -> None:
        """Leave the lockstep: its targets are owed no more."""
        self._lockstep.destroy()


def wait_up(procs, pred, timeout: float) -> bool:
    """:func:`wait_until` ``pred`` for node processes starting; one restart of a hung one.

    A node that has written nothing when ``timeout`` passes hung at
    start-up (rare: seen in a few test-suite runs, before the node's first
    line, ignoring SIGINT, so inside a C call; not yet explained); its stacks
    go to the output and it is started once more, as ``respawn`` would in a
    launch file, and waited for again.
    """
    if wait_until(pred, timeout):
        return True
    if not [p.restart_if_silent() for p in procs].count(True):
        return False
    return wait_until(pred, timeout)


def message_time(arrival: float, msg, sim_time: bool) -> float:
    """A recorded stamped message's time [s]: its stamp on simulation time, else its arrival.

    On simulation time the stamp (the time a pose was taken) is the same in
    every run, however late a busy computer delivered it; on the wall clock
    the recorder's times are the monotonic clock's, which stamps are not.
    """
    if not sim_time:
        return arrival
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def stop_all(procs: dict, first: str = 'inverse') -> dict:
    """Stop node processes: ``first`` (the controller) alone, then the others at once; exit codes.

    The controller vents as it stops, and its vent must reach the nodes
    that subscribe it while they still run (a lab stops its controller
    before its regulator driver for the same reason): stopped at the same
    moment as the simulated robot, the vent's acknowledgement took 2.1-2.6 s
    and the recorder missed it in about one run in ten.
    """
    codes = {}
    if first in procs:
        codes[first] = procs[first].stop()
    rest = {k: p for k, p in procs.items() if k != first}
    for p in rest.values():
        p.interrupt()                    # all at once: they shut down in parallel
    codes.update({k: p.stop() for k, p in reversed(list(rest.items()))})
    return codes


def wait_until(pred, timeout: float) -> bool:
    """Poll ``pred`` every 10 ms until true (True) or ``timeout`` seconds passed (False)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return False


def tidy(log_dir: Path, passed: bool) -> None:
    """Remove a job's temporary log folder when it passed; keep it (and say where) when not."""
    import shutil
    if passed:
        shutil.rmtree(log_dir, ignore_errors=True)
    else:
        print(f'  node logs kept in {log_dir}')
