"""A busy computer (issue 34 item 4): the closed loop's command path on a shared CPU.

Runs the closed loop on the wall clock, as with a real robot:
``simulated_robot_node`` (the robot's ``*_mismatched`` file, its realistic
plant) and ``inverse_kinetostatic_node`` (``feedback: integral``, its other
defaults; the model ``one_segment`` / ``two_segment``) as separate processes
on an isolated ``ROS_DOMAIN_ID``.  This process streams the targets at 50 Hz,
each stamped when it is published (not previewed; ``--planner timer``: each
the path at its timer tick's time, stamped after the tick by as long as the
computer kept this process waiting, a missed tick skipped, as a lab's
planner on a ROS timer), in phases: a held target
(8 s); the paper's circle at 10x its speed (2 s period), entered over a 1 s
spin-up, left over a 1 s spin-down after three periods of path, where it
started; held again (3 s); a 10 mm step in ``y``, held 4 s.  Each robot runs
``--repeats`` pairs (default 3), one run after the other: quiet, and busy,
with ``--burners`` CPU-bound processes (default: one per core, ``python -c
"while True: pass"`` at the nodes' priority) started before the nodes and
killed after them.  Each figure is the median of its condition's runs, its
range printed beside it: one run's figure moves by itself (the two-segment
circle's quiet RMSE was 0.090-0.177 mm in five single runs), and a target
stream's stall falls in the circle's measured period in some runs only.

Measured in each run:

* the command period: the intervals between ``pressure_command`` messages as
  this process's middleware received them (``received_timestamp``), against
  the nominal ``1 / feedback_rate_hz`` of the inverse node (the re-solve
  period of a held target; a streamed target is solved as it comes, so at
  50 Hz a command goes out every 20 ms); and, from the node's heartbeat, how
  many targets it received, how many commands were solves and how many its
  republishing of the last one (``command_rate_hz``, when no solve went out
  for half its period);
* the age of the newest measured pose at each solve: the inverse node's
  ``measured_pose_age_s`` in its per-solve status on ``/diagnostics`` (a
  sample of the solves: an unchanged status goes out at 10 Hz), outside the
  motion capture's dropouts (0.5 s every 15 s on the realistic plant: the
  simulator published ``true_pose`` but no ``measured_pose``);
* tracking, on the simulator's ground truth (``true_pose``) against the
  target wanted at that time: held RMSE over the last half of the first
  hold, circle RMSE over the second period at full speed, the step's
  overshoot along the step and its largest error from 1.5 s after it on (two
  segments: the angle RMSEs of the end-effector z-axis too);
* the oscillation watchdog's trips (``oscillation_trips`` on
  ``/diagnostics``) and whether every command was finite and within the
  robot file's limits (the check a regulator's side makes:
  ``contract.validate_pressure_input``);
* to read them by: the period of this process's own target stream, the
  solve times (the node's heartbeat: median, p95 and largest of its last
  1000 solves, about the whole stream; p99 of the per-solve statuses'
  sample), the share of the solves on the circle that held the correction
  for a target jump (``feedback_state``: the node's smooth jump transition
  took a late target for a jump), the CPU the nodes and the machine's
  other processes used meanwhile (the machine is shared: "quiet" means
  without the burners, not alone), and the scheduler the inverse node's
  threads ran on (its ``realtime_priority``: SCHED_FIFO where the bench
  has the privilege to grant it, as a lab sets up its controller).

Prints a table per robot, quiet against busy (medians) with the ratio
busy/quiet and the goals (every busy figure within 1.3x of the quiet one;
command period p99 at most 2x nominal; no watchdog trip; every command
safe), each condition's range beside them, and writes the figures to
``--out`` (default ``bench/busy.json``).  Exit status 1 when a run could not
be made (a node did not come up), else 0.

    .venv/bin/python bench/busy_bench.py [--robot one_segment|two_segment|both]
        [--burners N] [--repeats N] [--time-scale S] [--rig-nice N] [--out FILE]
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.loop import STEP_M, paper_circle
from bellow_ancf_ros.core.experiments import spin_down, spin_up
from bellow_ancf_ros.core.geometry import (angle_between, quaternion_from_z_axis,
                                           z_axis_from_quaternion)
from bellow_ancf_ros.demos.pipeline import (NodeProcess, SpunNode, child_env,
                                            hardware_parameters, record_qos, tidy, wait_up)
from family_bench import GOALS
from soak import proc_stats

HERE = Path(__file__).resolve().parent
ROBOTS = ('one_segment', 'two_segment')
TARGET_RATE_HZ = 50.0
PERIOD_S = 2.0        # the paper's circle at 10x its speed
SPIN_S = 1.0          # the circle's spin-up and spin-down
LATE_S = 1.5          # the step's error is judged from this long after it on
SEED = 7              # the motion capture's noise, outliers and dropouts
RATIO_GOAL = 1.3      # a busy figure at most this many times the quiet one
REPEATS = 3           # quiet and busy runs per robot: the figures are their medians
RIG_NICE_HELP = ("the simulated robot's niceness, its session's too (default 0: the nodes' and "
                 "the burners' priority; negative, with the privilege to: above them, as the "
                 'hardware it stands for, which a busy computer does not slow)')
PLANNERS = ('clock', 'timer')
PLANNER_HELP = ("how the bench's planner stamps its targets: clock (default), each pose the "
                'path at the time it is stamped with, when it is sent; timer, a lab\'s planner '
                "on a timer: each pose the path at its tick's time, stamped when it is sent "
                '(late by as long as the computer kept it waiting), a missed tick skipped')
PERIOD_GOAL = 2.0     # command period p99 at most this many nominal periods
GAP_S = 0.1           # measured poses this far apart (capture stamps): a gap
NOT_QUIET_CORES = 0.25   # other processes' CPU in the quiet run worth a warning [cores]
INVERSE = 'inverse_kinetostatic_node'
#: The tracking figures checked against the closed loop's goals (the family bench's GOALS).
TRACKED = {'held_mm': 'held position RMSE [mm]', 'held_deg': 'held angle RMSE [deg]',
           'circle_mm': 'circle 10x position RMSE [mm]',
           'circle_deg': 'circle 10x angle RMSE [deg]', 'overshoot_mm': 'step overshoot [mm]',
           'late_mm': 'step error 1.5 s after [mm]'}


def tracking_goals(n_segments: int) -> dict:
    """The tracking goals (figure -> largest allowed value) of a robot of ``n_segments``."""
    column = 2 if n_segments == 1 else 3
    return {key: GOALS[label][column] for key, label in TRACKED.items()
            if GOALS[label][column] is not None}


def nominal_period_s() -> float:
    """``1 / feedback_rate_hz`` at the inverse node's default (its parameter table)."""
    from bellow_ancf_ros.nodes.measured_feedback import FEEDBACK_PARAMETER_TABLE
    return 1.0 / next(p.default for p in FEEDBACK_PARAMETER_TABLE
                      if p.name == 'feedback_rate_hz')


# ------------------------------------------------------------------ the targets
@dataclass(frozen=True)
class Schedule:
    """The phases [s]: held, the circle (``circle_periods`` of path, 0: none), held, the step."""

    held_s: float = 8.0
    circle_periods: int = 3     # spin-up and spin-down included; the path ends where it began
    settle_s: float = 3.0       # held again after the circle, before the step
    after_s: float = 4.0        # the step target held (0: no step)

    def scaled(self, k: float) -> 'Schedule':
        """The holds ``k`` times as long (the circle keeps its period and its periods)."""
        return replace(self, held_s=k * self.held_s, settle_s=k * self.settle_s,
                       after_s=k * self.after_s)

    @property
    def full_s(self) -> float:
        """Time at full speed on the circle."""
        return max(self.circle_periods * PERIOD_S - SPIN_S, 0.0) if self.circle_periods else 0.0

    @property
    def circle_s(self) -> float:
        """The circle phase: spin-up, full speed, spin-down."""
        return self.full_s + 2 * SPIN_S if self.circle_periods else 0.0

    @property
    def circle_window(self) -> tuple | None:
        """The circle's second period at full speed (None: the circle has none)."""
        if self.full_s < 2 * PERIOD_S:
            return None
        a = self.held_s + SPIN_S + PERIOD_S
        return a, a + PERIOD_S

    @property
    def step_at(self) -> float | None:
        """When the step target starts (None: no step)."""
        return self.held_s + self.circle_s + self.settle_s if self.after_s > 0 else None

    @property
    def end_s(self) -> float:
        """The stream's length."""
        return self.held_s + self.circle_s + (self.settle_s + self.after_s
                                              if self.after_s > 0 else 0.0)


class Targets:
    """The target wanted at time ``t`` of the stream: ``(position, z-axis or None)``."""

    def __init__(self, cfg, schedule: Schedule) -> None:
        """The paper's circle for ``cfg`` at 10x, held at its start point around it."""
        self.s = schedule
        self.path = paper_circle(cfg, PERIOD_S)
        self.home = self.path(0.0)
        self.goal = self.home[0] + np.array([0.0, STEP_M, 0.0])

    def __call__(self, t: float):
        """The target at ``t`` seconds after the stream's start."""
        s = self.s
        c = t - s.held_s
        if s.circle_periods and 0.0 <= c < s.circle_s:
            if c < SPIN_S + s.full_s:
                tau = spin_up(c, SPIN_S)
            else:
                tau = SPIN_S / 2 + s.full_s + spin_down(c - SPIN_S - s.full_s, SPIN_S)
            return self.path(tau)
        if s.step_at is not None and t >= s.step_at:
            return self.goal, self.home[1]
        return self.home


# ------------------------------------------------------------------ this process's node
class BusyClient(SpunNode):
    """Targets out; commands (with their reception stamps), poses and diagnostics in."""

    def __init__(self, domain: int) -> None:
        """Publisher and subscriptions; spinning in its thread."""
        super().__init__(domain, 'busy_bench')
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from std_msgs.msg import Float64MultiArray

        from bellow_ancf_ros.nodes.ros_util import command_qos

        q = record_qos()
        self.pub = self.node.create_publisher(PoseStamped, 'target_pose', command_qos())
        self.commands = []   # (reception stamp ns, callback ns, data, label)
        self.true = []       # messages
        self.measured = []   # capture stamps [s]
        self.diag = []       # DiagnosticArray messages
        self.sent = []       # stamps [s] of the targets sent
        self.unmatched_s = 0.0   # how long the robot had not matched the commands when ready
        self._unmatched_since = 0.0
        self.late = []       # how long after its tick's time each was stamped [s]
        n = self.node
        n.create_subscription(Float64MultiArray, 'pressure_command', self._command, q)
        n.create_subscription(PoseStamped, 'true_pose', self._true, q)
        n.create_subscription(PoseStamped, 'measured_pose', self._measured, q)
        n.create_subscription(DiagnosticArray, '/diagnostics', self._diag, q)
        self.start()

    def _command(self, msg, info) -> None:
        now = time.time_ns()
        got = info.get('received_timestamp') if info is not None else None
        label = msg.layout.dim[0].label if msg.layout.dim else None
        with self.lock:
            self.commands.append((got or now, now, tuple(msg.data), label))

    def _true(self, msg) -> None:
        with self.lock:
            self.true.append(msg)

    def _measured(self, msg) -> None:
        with self.lock:
            self.measured.append(_stamp(msg))

    def _diag(self, msg) -> None:
        with self.lock:
            self.diag.append(msg)

    def inverse_active(self) -> bool:
        """True once the inverse node's heartbeat says ``active``."""
        with self.lock:
            diag = list(self.diag)
        return any(_values(st).get('lifecycle_state') == 'active'
                   for m in diag for st in m.status if st.name == f'{INVERSE}: status')

    def robot_matched(self) -> int | None:
        """The robot's newest status: publishers of its commands matched (None: none yet)."""
        with self.lock:
            diag = list(self.diag)
        for m in reversed(diag):
            for st in m.status:
                n = _values(st).get('command_publishers')
                if n is not None and st.name.endswith(': simulated robot'):
                    return int(n)
        return None

    def ready(self) -> bool:
        """The simulator publishes, the inverse node listens to targets and is active.

        And the simulated robot has matched the inverse node's commands: on a
        busy computer the discovery between the two can take a second or more
        after the inverse node is active, and a run started before then loses
        its first commands (the robot then steps to the newest at once).
        ``unmatched_s``: how long it waited for that (up to a status period, 1 s, more).
        """
        with self.lock:
            seen = bool(self.true)
        if not (seen and self.pub.get_subscription_count() >= 1 and self.inverse_active()):
            return False
        since = self._unmatched_since = self._unmatched_since or time.monotonic()
        if not self.robot_matched():
            return False
        self.unmatched_s = time.monotonic() - since
        return True

    def stream(self, targets: Targets, duration_s: float, planner: str = 'clock') -> float:
        """Stream ``targets`` at 50 Hz for ``duration_s``; its start [s, ROS].

        ``planner`` (:data:`PLANNERS`): ``clock``, each pose the path at the
        time it is stamped with, when it is published (late ticks catch up);
        ``timer``, a lab's
        planner on a timer: each pose the path at its tick's time, stamped
        when it is published, after the tick (late by as long as the
        computer kept this process waiting), a tick missed altogether
        skipped, as a ROS timer skips it.
        """
        from bellow_ancf_ros.nodes.ros_util import pose_message

        clock = self.node.get_clock()
        t0 = clock.now().nanoseconds * 1e-9
        start = time.monotonic()
        k = 0
        while k / TARGET_RATE_HZ <= duration_s:
            now = clock.now()
            t = k / TARGET_RATE_HZ if planner == 'timer' else now.nanoseconds * 1e-9 - t0
            pos, z = targets(t)
            q = (0.0, 0.0, 0.0, 1.0) if z is None else quaternion_from_z_axis(z)
            if planner == 'timer':
                now = clock.now()
            self.pub.publish(pose_message(pos, q, 'base', now.to_msg()))
            self.sent.append(now.nanoseconds * 1e-9)
            self.late.append(now.nanoseconds * 1e-9 - t0 - k / TARGET_RATE_HZ)
            k += 1
            if planner == 'timer':   # (the clock planner catches up, as it always did)
                k = max(k, math.ceil((time.monotonic() - start) * TARGET_RATE_HZ))
            time.sleep(max(0.0, start + k / TARGET_RATE_HZ - time.monotonic()))
        return t0

    def snapshot(self) -> dict:
        """A copy of everything recorded."""
        with self.lock:
            return {'commands': list(self.commands), 'true': list(self.true),
                    'measured': list(self.measured), 'diag': list(self.diag),
                    'sent': list(self.sent), 'late': list(self.late)}


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _values(status) -> dict:
    return {kv.key: kv.value for kv in status.values}


# ------------------------------------------------------------------ CPU accounting
def _machine_cpu() -> dict:
    """The machine's CPU time so far [s]: busy (user, nice, system, irq) and stolen."""
    f = [int(v) for v in Path('/proc/stat').read_text().split('\n', 1)[0].split()[1:]]
    tick = os.sysconf('SC_CLK_TCK')
    return {'busy': (f[0] + f[1] + f[2] + f[5] + f[6]) / tick, 'steal': f[7] / tick}


def _cpu(pids: dict) -> dict:
    """CPU time [s] of the machine, of ``pids`` (name -> pid) and of this process."""
    out = _machine_cpu()
    out.update({k: proc_stats(pid)['cpu_s'] for k, pid in pids.items()})
    t = os.times()
    out['bench'] = t.user + t.system
    out['wall'] = time.monotonic()
    return out


def _cpu_use(a: dict, b: dict) -> dict:
    """Cores used between two :func:`_cpu` readings: each part, ours, and everybody else's."""
    wall = b['wall'] - a['wall']
    use = {k: (b[k] - a[k]) / wall for k in a if k != 'wall'}
    ours = sum(v for k, v in use.items() if k not in ('busy', 'steal'))
    # (the machine's ticks and the processes' are read apart: a few ticks either way)
    use['others'] = max(use['busy'] - ours, 0.0)
    use['burners'] = sum(v for k, v in use.items() if k.startswith('burner'))
    return {k: round(v, 3) for k, v in use.items()}


# ------------------------------------------------------------------ one run
def scheduling(pid: int) -> dict:
    """The scheduler of a process's threads: how many, how many on SCHED_FIFO, their priority.

    Read from ``/proc/<pid>/task/*/stat`` (fields 40 and 41: the real-time
    priority and the policy, 1 for SCHED_FIFO); the inverse node asks for
    SCHED_FIFO itself (its ``realtime_priority``).
    """
    fifo, prio, n = 0, 0, 0
    for task in Path(f'/proc/{pid}/task').glob('*'):
        try:
            fields = (task / 'stat').read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        n += 1
        if int(fields[38]) == 1:   # (fields 41 and 40 counted from the first, after the name)
            fifo += 1
            prio = max(prio, int(fields[37]))
    return {'threads': n, 'fifo': fifo, 'priority': prio}


#: A burner: ends with the process that started it (the kernel's parent-death signal; a test
#: run killed before it stopped its burners left them loading both cores for later runs).
BURNER = ('import ctypes, os, signal, sys\n'
          'ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)   # PR_SET_PDEATHSIG\n'
          'if os.getppid() != int(sys.argv[1]):   # (its starter had gone already)\n'
          '    sys.exit()\n'
          'while True: pass')


def start_burners(n: int) -> list:
    """``n`` CPU-bound processes (``python -c "while True: pass"``), at our priority.

    Started from the main thread: each ends when this process does (a parent
    death signal fires when the thread that started the process ends).
    """
    return [subprocess.Popen([sys.executable, '-c', BURNER, str(os.getpid())],
                             stdin=subprocess.DEVNULL, start_new_session=True)
            for _ in range(n)]


def stop_burners(burners: list) -> None:
    """Kill the burners (each by its pid) and reap them."""
    for p in burners:
        p.kill()
    for p in burners:
        p.wait(5.0)


def run_loop(robot: str, burners: int, schedule: Schedule = Schedule(), seed: int = SEED,
             startup_timeout: float = 90.0, env_extra: dict | None = None,
             identified: bool = True, rig_nice: int = 0, planner: str = 'clock') -> dict:
    """One run of the closed loop (``burners`` beside it): its figures (:func:`figures`).

    ``planner``: how the targets are stamped (:meth:`BusyClient.stream`).

    ``identified``: the inverse node is told the plant's hardware as a lab
    that identified it (``hardware_parameters``: the regulators' play, the
    bellows' creep, the correction carried in the model's frame), as
    ``make demo`` runs it; False: the node's bare defaults.
    ``rig_nice``: the simulated robot's niceness (:data:`RIG_NICE_HELP`).
    ``env_extra``: more environment for the node processes.  Raises
    ``RuntimeError`` when the nodes do not come up or one dies (its log
    is kept and named).
    """
    cfg = load_robot(robot)
    targets = Targets(cfg, schedule)
    domain = random.randint(1, 101)
    env = dict(child_env(domain), **(env_extra or {}))
    logs = Path(tempfile.mkdtemp(prefix='bellow_ancf_busy_'))
    burn = start_burners(burners)
    procs, client, ok = {}, None, False
    try:
        time.sleep(0.5)   # the burners at full speed before the nodes start
        procs['robot'] = NodeProcess('simulated_robot_node', {
            'robot_config': f'{robot}_mismatched', 'seed': seed}, env, logs, nice=rig_nice)
        procs['inverse'] = NodeProcess(INVERSE, {
            'robot_config': robot, 'feedback': 'integral',
            **(hardware_parameters('realistic') if identified else {})}, env, logs)
        client = BusyClient(domain)
        t_start = time.monotonic()
        if not wait_up(procs.values(), client.ready, startup_timeout):
            raise RuntimeError(f'the nodes did not come up within {startup_timeout:g} s')
        startup_s, unmatched_s = time.monotonic() - t_start, client.unmatched_s
        pids = {k: p.proc.pid for k, p in procs.items()}
        sched = scheduling(pids['inverse'])
        pids.update({f'burner{i}': p.pid for i, p in enumerate(burn)})
        cpu0 = _cpu(pids)
        t0 = client.stream(targets, schedule.end_s, planner)
        cpu1 = _cpu(pids)
        time.sleep(0.3)   # the last answers in
        dead = [k for k, p in procs.items() if not p.alive()]
        if dead:
            raise RuntimeError(f'node(s) died during the run: {dead}')
        data = client.snapshot()
        ok = True
    finally:
        for p in procs.values():
            p.interrupt()
        codes = {k: p.stop() for k, p in procs.items()}
        if client is not None:
            client.close()
        stop_burners(burn)
        if not ok:
            print('  ' + '\n  '.join(f'--- {p.module} log (last lines):\n{p.tail()}'
                                     for p in procs.values()))
        tidy(logs, ok)
    out = figures(data, cfg, targets, t0)
    out.update(burners=burners, startup_s=round(startup_s, 2), exit_codes=codes,
               startup_unmatched_s=round(unmatched_s, 2),
               cpu_cores=_cpu_use(cpu0, cpu1), inverse_scheduling=sched)
    return out


# ------------------------------------------------------------------ figures
def _pct(x, q) -> float | None:
    return float(np.percentile(x, q)) if len(x) else None


def _ms(x) -> dict:
    """Median, p99 and largest of ``x`` [s], in ms."""
    x = np.asarray(x, dtype=float) * 1e3
    return {'p50': _pct(x, 50), 'p99': _pct(x, 99), 'max': float(x.max()) if len(x) else None,
            'n': int(len(x))}


def _rms(x) -> float | None:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else None


def dropouts(measured: list, true_stamps: np.ndarray) -> list:
    """The motion capture's dropouts: gaps in its capture stamps while ``true_pose`` flowed.

    A gap without true poses either is the simulator itself held up (a CPU
    stall), not a dropout.
    """
    m = np.sort(np.asarray(measured, dtype=float))
    out = []
    for a, b in zip(m[:-1], m[1:]):
        if b - a > GAP_S:
            inside = np.count_nonzero((true_stamps > a) & (true_stamps < b))
            if inside >= 0.5 * (b - a) / GAP_S:   # true poses at 120 Hz: far more than this
                out.append((float(a), float(b)))
    return out


def figures(data: dict, cfg, targets: Targets, t0: float) -> dict:
    """The figures of one run's recording (``t0``: the stream's start, ROS time [s])."""
    from bellow_ancf_ros.nodes import contract

    s = targets.s
    end = t0 + s.end_s
    out = {}
    # ---- commands: period, safety (every command recorded, the vent too)
    cmds = data['commands']
    bad = []
    for _, _, values, label in cmds:
        try:
            contract.validate_pressure_input(values, 'Pa', cfg.n_actuators_total, cfg.p_min,
                                             cfg.p_max, label)
        except contract.InputError as exc:
            bad.append(str(exc))
    window = [c for c in cmds if t0 + 0.5 <= c[0] * 1e-9 <= end]
    rx = np.array([c[0] for c in window], dtype=float) * 1e-9
    cb = np.array([c[1] for c in window], dtype=float) * 1e-9
    out['period_ms'] = _ms(np.diff(rx))
    out['callback_period_ms'] = _ms(np.diff(cb))
    out['gaps_over_0_5_s'] = int(np.count_nonzero(np.diff(rx) > 0.5))
    out['commands'] = len(cmds)
    out['commands_bad'] = len(bad)
    out['commands_bad_examples'] = bad[:3]
    out['commands_safe'] = bool(cmds) and not bad
    sent = np.array(data['sent'])
    out['target_period_ms'] = _ms(np.diff(sent))
    out['target_late_ms'] = _ms(np.array(data.get('late', [])))
    # ---- diagnostics: the inverse node's per-solve statuses and heartbeats, the simulator's
    true_stamps = np.array([_stamp(m) for m in data['true']])
    drops = dropouts(data['measured'], true_stamps)
    ages, solves, trips, sim_refused, errors = [], [], 0, 0, []
    on_circle = []   # per-solve statuses on the circle: holding for a target jump?
    trip_seen = []   # (stamp, the watchdog's trips so far)
    beats = []   # the inverse node's heartbeats: (stamp, counters)
    for arr in data['diag']:
        t = _stamp(arr)
        for st in arr.status:
            v = _values(st)
            if st.name == f'{INVERSE}: status':
                beats.append((t, {k[8:]: int(x) for k, x in v.items()
                                  if k.startswith('targets_') and x.isdigit()}, v))
            if st.name.startswith(INVERSE):
                trip_seen.append((t, int(v.get('oscillation_trips', 0))))
                if 'oscillat' in st.message.lower() and st.message not in errors:
                    errors.append(st.message)
            if st.name == f'{INVERSE}: inverse kinetostatics' and t0 <= t <= end:
                if 'solve_time_ms' in v:
                    solves.append(float(v['solve_time_ms']) * 1e-3)
                if s.circle_periods and 0.0 <= t - t0 - s.held_s <= s.circle_s:
                    on_circle.append('jump' in v.get('feedback_state', ''))
                age = v.get('measured_pose_age_s', 'none')
                if age != 'none' and not any(a <= t <= b + 0.15 for a, b in drops):
                    ages.append(float(age))
            if 'simulated robot' in st.name:
                sim_refused = max(sim_refused, int(v.get('refused', 0)))
    # counters over the stream: the last heartbeat before it to the last one recorded
    before = [c for t, c, _ in beats if t <= t0]
    out['counts'], out['solve_window_ms'] = {}, {}
    if before and beats:
        last = beats[-1][1]
        out['counts'] = {k: last[k] - before[-1].get(k, 0) for k in last}
        # the node's own solve times over its last (up to) 1000 solves: about the whole stream
        v = beats[-1][2]
        out['solve_window_ms'] = {k: float(v[f'solve_ms_{k}']) for k in ('median', 'p95', 'max')
                                  if v.get(f'solve_ms_{k}', 'n/a') != 'n/a'}
        out['solve_window_ms']['n'] = int(v.get('solve_stats_window', 0))
        out['carries'] = {k: int(v[f'feedback_{k}']) for k in ('carries', 'carries_cut')
                          if str(v.get(f'feedback_{k}', '')).isdigit()}
    trip_at = []   # when each trip was first reported [s after the stream's start]
    for t, k in sorted(trip_seen):
        trip_at += [round(t - t0, 2)] * (k - trips)
        trips = max(trips, k)
    out['trip_at_s'] = trip_at
    out['age_ms'] = _ms(ages)
    out['circle_jump_pct'] = 100.0 * float(np.mean(on_circle)) if on_circle else None
    out['dropouts'] = len(drops)
    out['solve_ms'] = _ms(solves)
    out['trips'] = trips
    out['oscillation_messages'] = errors[:3]
    out['sim_refused'] = sim_refused
    # ---- tracking on the ground truth, against the target wanted then
    rel = true_stamps - t0
    pos = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                    for m in data['true']]).reshape(-1, 3)
    ref = [targets(t) for t in rel]
    ref_p = np.array([r[0] for r in ref]).reshape(-1, 3)
    err = np.linalg.norm(pos - ref_p, axis=1)
    two = cfg.n_segments >= 2
    if two:
        z = np.array([z_axis_from_quaternion((m.pose.orientation.x, m.pose.orientation.y,
                                              m.pose.orientation.z, m.pose.orientation.w))
                      for m in data['true']]).reshape(-1, 3)
        ang = np.degrees(angle_between(z, np.array([r[1] for r in ref]).reshape(-1, 3)))
    held = (rel >= s.held_s / 2) & (rel <= s.held_s)
    out['held_rmse_mm'] = _mm(_rms(err[held]))
    out['held_rmse_deg'] = _rms(ang[held]) if two else None
    out['circle_rmse_mm'] = out['circle_rmse_deg'] = None
    if s.circle_window is not None:
        a, b = s.circle_window
        on = (rel >= a) & (rel <= b)
        out['circle_rmse_mm'] = _mm(_rms(err[on]))
        out['circle_rmse_deg'] = _rms(ang[on]) if two else None
    out['step_overshoot_mm'] = out['step_late_mm'] = None
    if s.step_at is not None:
        after = (rel >= s.step_at) & (rel <= s.end_s)
        late = (rel >= s.step_at + LATE_S) & (rel <= s.end_s)
        u = np.array([0.0, 1.0, 0.0])
        if after.any():
            out['step_overshoot_mm'] = max(float(np.max((pos[after] - targets.goal) @ u)),
                                           0.0) * 1e3
        if late.any():
            out['step_late_mm'] = float(np.linalg.norm(pos[late] - targets.goal,
                                                       axis=1).max()) * 1e3
    out['true_poses'] = int(len(rel))
    return out


def _mm(v):
    return None if v is None else v * 1e3


# ------------------------------------------------------------------ the table
#: (figure, label, the value's key path); a busy figure at most RATIO_GOAL times the quiet one
ROWS = (
    ('period_p50', 'command period p50 [ms]', ('period_ms', 'p50')),
    ('period_p99', 'command period p99 [ms]', ('period_ms', 'p99')),
    ('period_max', 'command period max [ms]', ('period_ms', 'max')),
    ('age_p50', 'measurement age at a solve p50 [ms]', ('age_ms', 'p50')),
    ('age_p99', 'measurement age at a solve p99 [ms]', ('age_ms', 'p99')),
    ('held_mm', 'held RMSE [mm]', ('held_rmse_mm',)),
    ('held_deg', 'held angle RMSE [deg]', ('held_rmse_deg',)),
    ('circle_mm', 'circle 10x RMSE, 2nd period [mm]', ('circle_rmse_mm',)),
    ('circle_deg', 'circle 10x angle RMSE [deg]', ('circle_rmse_deg',)),
    ('overshoot_mm', 'step overshoot [mm]', ('step_overshoot_mm',)),
    ('late_mm', f'step error from {LATE_S:g} s after [mm]', ('step_late_mm',)),
)
#: figures shown to read the others by (no goal)
INFO_ROWS = (
    ('command period p99 at callback [ms]', ('callback_period_ms', 'p99')),
    ('targets received by the inverse node', ('counts', 'received')),
    ('commands from solves', ('counts', 'published')),
    ('commands republished (no solve for 25 ms)', ('counts', 'republished')),
    ('solves over their budget', ('counts', 'over_budget')),
    ('target stream period p99 [ms]', ('target_period_ms', 'p99')),
    ('target stream period max [ms]', ('target_period_ms', 'max')),
    ("targets' stamps after their ticks p50 [ms]", ('target_late_ms', 'p50')),
    ("targets' stamps after their ticks p99 [ms]", ('target_late_ms', 'p99')),
    ('solve time median [ms] (last 1000 solves)', ('solve_window_ms', 'median')),
    ('solve time p95 [ms] (last 1000 solves)', ('solve_window_ms', 'p95')),
    ('solve time max [ms] (last 1000 solves)', ('solve_window_ms', 'max')),
    ('solve time p99 [ms] (10 Hz sample)', ('solve_ms', 'p99')),
    ('circle: solves holding for a jump [%]', ('circle_jump_pct',)),
    ("jumps' goals the correction was carried to", ('carries', 'carries')),
    ('... of them cut short (a solve failed)', ('carries', 'carries_cut')),
    ('mocap dropouts (ages left out)', ('dropouts',)),
    ('CPU: inverse node [cores]', ('cpu_cores', 'inverse')),
    ('CPU: simulated robot [cores]', ('cpu_cores', 'robot')),
    ('CPU: this bench [cores]', ('cpu_cores', 'bench')),
    ('CPU: the burners [cores]', ('cpu_cores', 'burners')),
    ('CPU: other processes [cores]', ('cpu_cores', 'others')),
    ('CPU: stolen by the host [cores]', ('cpu_cores', 'steal')),
)


def _get(run: dict, path: tuple):
    v = run
    for k in path:
        v = None if v is None else v.get(k)
    return v


def _put(run: dict, path: tuple, value) -> None:
    for k in path[:-1]:
        run = run.setdefault(k, {})
    run[path[-1]] = value


def combined(runs: list) -> dict:
    """The repeats of one condition as one run: each figure's median, the worst of the checks.

    Every figure of :data:`ROWS` and :data:`INFO_ROWS` is the median of
    the repeats that have it (None where none has); ``spread``: each goal
    figure's ``(min, max)`` over the repeats; the watchdog's trips are
    summed, ``commands_safe`` holds only if it held in every repeat, and
    the messages and trip times are every repeat's (the start-up and
    counts are the first repeat's, the inverse node's scheduler the one of
    the repeat with the fewest threads on SCHED_FIFO).
    """
    out = copy.deepcopy(runs[0])
    out['spread'] = {}
    for key, path in [(k, p) for k, _, p in ROWS] + [(None, p) for _, p in INFO_ROWS]:
        vals = [v for v in (_get(r, path) for r in runs) if v is not None]
        if vals:
            _put(out, path, float(np.median(vals)))
            if key is not None:   # (a goal figure)
                out['spread'][key] = (float(min(vals)), float(max(vals)))
    out['trips'] = int(sum(r['trips'] for r in runs))
    out['commands_safe'] = all(r['commands_safe'] for r in runs)
    for key in ('trip_at_s', 'oscillation_messages', 'commands_bad_examples'):
        out[key] = [x for r in runs for x in r[key]]
    sched = [r['inverse_scheduling'] for r in runs if r.get('inverse_scheduling')]
    if sched:   # (the run with the fewest threads on the real-time scheduler)
        out['inverse_scheduling'] = min(sched, key=lambda x: (x['fifo'], -x['threads']))
    out['repeats'] = len(runs)
    return out


def compare(quiet: dict, busy: dict, nominal_s: float, limits: dict | None = None) -> list:
    """The goal rows: figure, quiet, busy, ratio, goal text, met (None: no figure).

    ``limits``: figure -> the largest value allowed in both runs
    (:func:`tracking_goals`), beside the ratio.
    """
    rows = []
    limits = limits or {}
    limit_ms = PERIOD_GOAL * nominal_s * 1e3
    for key, label, path in ROWS:
        q, b = _get(quiet, path), _get(busy, path)
        if q is None and b is None:
            continue
        ratio = (b / q if q else math.inf) if q is not None and b is not None else None
        goal = f'busy <= {RATIO_GOAL:g}x quiet'
        met = ratio is not None and ratio <= RATIO_GOAL
        if key == 'period_p99':
            goal += f', both <= {limit_ms:g} ms'
            met = met and q <= limit_ms and b <= limit_ms
        elif key in limits:
            goal += f', both <= {limits[key]:g}'
            met = met and q <= limits[key] and b <= limits[key]
        rows.append({'figure': key, 'label': label, 'quiet': q, 'busy': b, 'ratio': ratio,
                     'goal': goal, 'met': bool(met),
                     'quiet_range': quiet.get('spread', {}).get(key),
                     'busy_range': busy.get('spread', {}).get(key)})
    for key, label, ok in (
            ('trips', 'oscillation watchdog trips', lambda r: r['trips'] == 0),
            ('commands_safe', 'every command finite, within limits',
             lambda r: r['commands_safe'])):
        rows.append({'figure': key, 'label': label, 'quiet': quiet[key], 'busy': busy[key],
                     'ratio': None, 'goal': '0' if key == 'trips' else 'yes',
                     'met': bool(ok(quiet) and ok(busy))})
    return rows


def phase(schedule: dict, t: float) -> str:
    """The phase of the stream at ``t`` seconds (``schedule``: a :class:`Schedule` as a dict)."""
    s = Schedule(**schedule)
    ends = [('held', s.held_s)]
    if s.circle_periods:
        ends += [('circle spin-up', s.held_s + SPIN_S), ('circle', s.held_s + SPIN_S + s.full_s),
                 ('circle spin-down', s.held_s + s.circle_s)]
    ends.append(('held again', s.step_at if s.step_at is not None else math.inf))
    for name, end in ends:
        if t < end:
            return name
    return 'after the step'


def _cell(v) -> str:
    if v is None:
        return 'n/a'
    if isinstance(v, bool):
        return 'yes' if v else 'NO'
    if isinstance(v, int):
        return str(v)
    return f'{v:.3f}' if abs(v) < 10 else f'{v:.1f}'


def render(result: dict) -> str:
    """One robot's table: quiet against busy, the ratio, the goals; then the figures to read."""
    q, b = result['quiet'], result['busy']
    n = b.get('repeats', 1)
    lines = [f"{result['robot']}: quiet vs busy ({b['burners']} burner(s) on "
             f"{result['cpu_count']} cores), targets at {TARGET_RATE_HZ:g} Hz stamped when "
             f"sent; nominal command period {result['nominal_period_ms']:g} ms "
             '(1 / feedback_rate_hz)'
             + (f'; medians of {n} runs each, their range after them' if n > 1 else '')
             + (f"; the simulated robot at nice {result['rig_nice']}"
                if result.get('rig_nice') else ''),
             f"  {'figure':40s} {'quiet':>8s} {'busy':>8s} {'busy/quiet':>10s}  "
             f"{'goal':48s} met" + ('  quiet range      busy range' if n > 1 else '')]
    for r in result['rows']:
        ratio = 'n/a' if r['ratio'] is None else f"{r['ratio']:.2f}"
        spread = ''
        if n > 1 and r.get('quiet_range') and r.get('busy_range'):
            spread = ''.join(f"  {_cell(lo):>7s}-{_cell(hi):<7s}"
                             for lo, hi in (r['quiet_range'], r['busy_range']))
        lines.append(f"  {r['label']:40s} {_cell(r['quiet']):>8s} {_cell(r['busy']):>8s} "
                     f"{ratio:>10s}  {r['goal']:48s} {'yes' if r['met'] else 'NO':3s}{spread}")
    lines.append('  to read them by:')
    for label, path in INFO_ROWS:
        qv, bv = _get(q, path), _get(b, path)
        ratio = f'{bv / qv:.2f}' if qv and bv is not None else 'n/a'
        lines.append(f"  {label:40s} {_cell(qv):>8s} {_cell(bv):>8s} {ratio:>10s}")
    for name, run in (('quiet', q), ('busy', b)):
        sc = run.get('inverse_scheduling')
        if sc:
            lines.append(f"  {name}: the inverse node's threads on SCHED_FIFO "
                         f"{sc['fifo']} of {sc['threads']}"
                         + (f" (priority {sc['priority']})" if sc['fifo'] else ''))
    lines.append(f"  start-up {q['startup_s']:g} s quiet, {b['startup_s']:g} s busy; "
                 f"commands {q['commands']} / {b['commands']}; true poses "
                 f"{q['true_poses']} / {b['true_poses']}")
    others = q['cpu_cores'].get('others', 0.0)
    if others > NOT_QUIET_CORES:
        lines.append(f'  the quiet run was not alone: other processes used {others:.2f} '
                     'cores meanwhile (a shared machine)')
    for name, run in (('quiet', q), ('busy', b)):
        for m in run['oscillation_messages'] + run['commands_bad_examples']:
            lines.append(f'  {name}: {m}')
        if run['trip_at_s']:
            lines.append(f'  {name}: watchdog trips reported at '
                         + ', '.join(f'{t:g} s ({phase(result["schedule"], t)})'
                                     for t in run['trip_at_s']) + ' of the stream')
    missed = [r['label'] for r in result['rows'] if not r['met']]
    lines.append(f"  goals met: {len(result['rows']) - len(missed)} of {len(result['rows'])}"
                 + (f"; missed: {', '.join(missed)}" if missed else ''))
    return '\n'.join(lines)


def main(argv=None) -> int:
    """Run quiet and busy per robot, print the tables, write the JSON file."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--robot', choices=ROBOTS + ('both',), default='both')
    ap.add_argument('--burners', type=int, default=os.cpu_count() or 1,
                    help='CPU-bound processes beside the nodes in the busy run '
                         '(default: one per core)')
    ap.add_argument('--time-scale', type=float, default=1.0,
                    help="the holds' durations times this (the circle keeps its periods)")
    ap.add_argument('--repeats', type=int, default=REPEATS,
                    help='quiet and busy runs per robot, interleaved; the figures are their '
                         f'medians (default {REPEATS})')
    ap.add_argument('--rig-nice', type=int, default=0, help=RIG_NICE_HELP)
    ap.add_argument('--planner', choices=PLANNERS, default='clock', help=PLANNER_HELP)
    ap.add_argument('--out', type=Path, default=HERE / 'busy.json')
    ap.add_argument('--node-defaults', action='store_true',
                    help="the inverse node's bare defaults (default: told the plant's play and "
                         'creep as a lab that identified them, as make demo runs it)')
    args = ap.parse_args(argv)
    if args.burners < 1 or args.repeats < 1 or not args.time_scale > 0:
        print('--burners and --repeats must be at least 1 and --time-scale positive',
              file=sys.stderr)
        return 2
    from bellow_ancf_ros.core import limit_blas_threads
    limit_blas_threads()
    robots = ROBOTS if args.robot == 'both' else (args.robot,)
    schedule = Schedule().scaled(args.time_scale)
    nominal = nominal_period_s()
    results = {}
    for robot in robots:
        each = {'quiet': [], 'busy': []}
        for k in range(args.repeats):
            for name, n in (('quiet', 0), ('busy', args.burners)):
                print(f'{robot}, {name} ({k + 1} of {args.repeats}): {schedule.end_s:g} s of '
                      'targets ...', flush=True)
                try:
                    each[name].append(run_loop(robot, n, schedule, rig_nice=args.rig_nice,
                                               identified=not args.node_defaults,
                                               planner=args.planner))
                except RuntimeError as exc:
                    print(f'  FAILED: {exc}')
                    return 1
        runs = {name: combined(got) for name, got in each.items()}
        rows = compare(runs['quiet'], runs['busy'], nominal,
                       tracking_goals(load_robot(robot).n_segments))
        results[robot] = dict(robot=robot, cpu_count=os.cpu_count(),
                              node_parameters=('identified hardware' if not args.node_defaults
                                               else 'defaults'),
                              nominal_period_ms=nominal * 1e3, schedule=asdict(schedule),
                              rows=rows, repeats=each, rig_nice=args.rig_nice,
                              planner=args.planner, **runs)
        print(render(results[robot]), flush=True)
    data = {'schedule': asdict(schedule), 'target_rate_hz': TARGET_RATE_HZ,
            'circle_period_s': PERIOD_S, 'spin_s': SPIN_S, 'seed': SEED,
            'ratio_goal': RATIO_GOAL, 'period_goal_nominal': PERIOD_GOAL,
            'nominal_period_s': nominal, 'cpu_count': os.cpu_count(),
            'burners': args.burners, 'repeats': args.repeats, 'rig_nice': args.rig_nice,
            'robots': results}
    args.out.write_text(json.dumps(data, indent=1) + '\n')
    print(f'written: {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
