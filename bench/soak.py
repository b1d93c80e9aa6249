"""Soak of the closed loop with faults (``make soak``): hours, not minutes, in ten.

Runs, as separate processes on an isolated ``ROS_DOMAIN_ID``:
``inverse_kinetostatic_node`` (``feedback:=integral``, one segment),
``simulated_robot_node`` (the mismatched robot), ``forward_kinetostatic_node``
(predictions from the measured pressures); this process streams targets at
100 Hz along the paper's planar circle and injects faults in turn:

* ``configure``: first, 50 configure cycles of the inverse node (deactivate,
  cleanup, configure, activate), its RSS after each (a leak per configure
  shows here);
* ``sim_kill``: the simulated robot killed (SIGKILL) and restarted;
* ``stop_inverse`` / ``stop_forward``: SIGSTOP for 1 s, then SIGCONT;
* ``burst``: 10,000 targets as fast as they can be published;
* ``bad_input``: NaN, inf and wrong-frame targets and measured poses;
* ``payload``: ``payload_kg`` 0.05 for 5 s, then 0 (the model is not told
  the truth: the loop corrects);
* ``lifecycle``: 5 deactivate/activate cycles (each must vent);
* ``robot_switch``: the controller's robot file switched through the
  lifecycle (to the robot's own file and back, one fault each).

Every ``--sample-s`` (30 s) it prints a row per node (RSS, CPU, threads,
file descriptors) and for the loop (latency target stamp -> commanded pose,
targets answered, tracking error); at the end a summary (growth per minute,
latency early against late, bad outputs, recovery time after each fault)
and a verdict.  Every ``pressure_command`` is checked: finite and within the
robot file's limits (a bad output fails the soak).

    .venv/bin/python bench/soak.py --minutes 10
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import sys
import tempfile
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.model import find_shipped
from bellow_ancf_ros.core.experiments import trajectory
from bellow_ancf_ros.demos.pipeline import NodeProcess, SpunNode, child_env, wait_until

FAULTS = ('sim_kill', 'stop_inverse', 'stop_forward', 'burst', 'bad_input', 'payload',
          'lifecycle', 'robot_switch')
INVERSE = '/inverse_kinetostatic_node'
#: RSS growth per minute beyond which a node is said to grow (noise of the allocator and the
#: DDS buffers over a 10-minute run is well below it)
GROWTH_LIMIT_MIB_PER_MIN = 0.5
#: a fault is recovered from when the tracking error's median over 0.5 s is back below
#: RECOVERY_FACTOR times its median before the fault plus RECOVERY_SLACK_M
RECOVERY_FACTOR, RECOVERY_SLACK_M = 1.5, 0.1e-3
#: configure cycles after which the inverse node's RSS is judged (the plateau is reached)
SETTLE_CYCLES = 20


# ------------------------------------------------------------------ processes
def proc_stats(pid: int) -> dict:
    """RSS [MiB], CPU time [s], threads and open file descriptors of process ``pid``."""
    out = {'rss_mib': math.nan, 'cpu_s': math.nan, 'threads': -1, 'fds': -1}
    try:
        status = Path(f'/proc/{pid}/status').read_text()
        for line in status.splitlines():
            if line.startswith('VmRSS:'):
                out['rss_mib'] = int(line.split()[1]) / 1024.0
            elif line.startswith('Threads:'):
                out['threads'] = int(line.split()[1])
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        out['cpu_s'] = (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
        out['fds'] = len(os.listdir(f'/proc/{pid}/fd'))
    except (OSError, ValueError, IndexError):
        pass
    return out


# ------------------------------------------------------------------ the client
class SoakClient(SpunNode):
    """Targets out; commands, commanded and measured poses in, aggregated per window."""

    def __init__(self, domain: int, cfg) -> None:
        """Publishers, subscriptions and the service clients of the inverse node."""
        super().__init__(domain, 'soak_client')
        from geometry_msgs.msg import PoseStamped
        from lifecycle_msgs.srv import ChangeState
        from rcl_interfaces.srv import SetParameters
        from std_msgs.msg import Float64MultiArray

        from bellow_ancf_ros.nodes.ros_util import command_qos

        self.PoseStamped = PoseStamped
        self.cfg = cfg
        q = command_qos()
        self.pub_target = self.node.create_publisher(PoseStamped, 'target_pose', q)
        self.pub_meas = self.node.create_publisher(PoseStamped, 'measured_pose', q)
        self.node.create_subscription(Float64MultiArray, 'pressure_command', self._command, 100)
        self.node.create_subscription(PoseStamped, 'commanded_pose', self._commanded, 100)
        self.node.create_subscription(PoseStamped, 'measured_pose', self._measured, 100)
        self.set_params = self.node.create_client(SetParameters, f'{INVERSE}/set_parameters')
        self.change_state = self.node.create_client(ChangeState, f'{INVERSE}/change_state')
        self.sent = {}            # target stamp (ns) -> send time (monotonic)
        self.answered = set()
        self.latencies = []       # window: (send time, latency s)
        self.targets = deque(maxlen=4000)   # (stamp ns, position) in time order
        self.errors = deque()     # (monotonic time, tracking error m)
        self.commands = self.bad = self.vents = 0
        self.bad_examples = []
        self.start()

    # ------------------------------------------------------------ callbacks
    def _command(self, msg) -> None:
        label = msg.layout.dim[0].label if msg.layout.dim else ''
        scale = 1e3 if label.endswith('_kpa') else 1.0
        p = np.asarray(msg.data, dtype=float) * scale
        cfg = self.cfg
        ok = (p.size == 3 and np.all(np.isfinite(p))
              and np.all(p >= cfg.p_min - 1e-6) and np.all(p <= cfg.p_max + 1e-6))
        with self.lock:
            self.commands += 1
            if not ok:
                self.bad += 1
                if len(self.bad_examples) < 5:
                    self.bad_examples.append(p.tolist())
            if ok and not np.any(p):
                self.vents += 1

    def _commanded(self, msg) -> None:
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        now = time.monotonic()
        with self.lock:
            t_sent = self.sent.get(key)
            if t_sent is not None and key not in self.answered:
                self.answered.add(key)
                self.latencies.append((t_sent, now - t_sent))

    def _measured(self, msg) -> None:
        if msg.header.frame_id != 'base':
            return   # one of our own bad ones
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        p = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
        if not np.all(np.isfinite(p)):
            return
        with self.lock:
            target = None
            for stamp, pos in reversed(self.targets):
                if stamp <= key:
                    target = pos
                    break
            if target is not None:
                self.errors.append((time.monotonic(), float(np.linalg.norm(p - target))))
                while self.errors and self.errors[0][0] < time.monotonic() - 120.0:
                    self.errors.popleft()

    # ------------------------------------------------------------ output
    def pose(self, p, frame='base', stamp_ns=None):
        msg = self.PoseStamped()
        msg.header.frame_id = frame
        stamp_ns = time.time_ns() if stamp_ns is None else stamp_ns
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in p)
        msg.pose.orientation.w = 1.0
        return msg

    def send_target(self, p) -> None:
        stamp = time.time_ns()
        with self.lock:
            self.sent[stamp] = time.monotonic()
            self.targets.append((stamp, np.asarray(p, dtype=float)))
            if len(self.sent) > 20000:   # forget the oldest half
                for k in sorted(self.sent)[:10000]:
                    self.sent.pop(k, None)
                    self.answered.discard(k)
        self.pub_target.publish(self.pose(p, stamp_ns=stamp))

    # ------------------------------------------------------------ services
    def _call(self, client, request, timeout=10.0):
        if not client.wait_for_service(timeout_sec=timeout):
            raise RuntimeError(f'service {client.srv_name} not available')
        fut = client.call_async(request)
        if not wait_until(fut.done, timeout):
            raise RuntimeError(f'service {client.srv_name}: no answer in {timeout:g} s')
        return fut.result()

    def set_parameter(self, name, value) -> bool:
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        req = SetParameters.Request()
        req.parameters = [Parameter(name, value=value).to_parameter_msg()]
        return bool(self._call(self.set_params, req).results[0].successful)

    def transition(self, label: str) -> bool:
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        ids = {'configure': Transition.TRANSITION_CONFIGURE,
               'cleanup': Transition.TRANSITION_CLEANUP,
               'activate': Transition.TRANSITION_ACTIVATE,
               'deactivate': Transition.TRANSITION_DEACTIVATE}
        req = ChangeState.Request()
        req.transition.id = ids[label]
        return bool(self._call(self.change_state, req).success)

    def window(self, since: float) -> dict:
        """Latency and tracking figures of what happened since ``since`` (monotonic)."""
        until = time.monotonic() - 0.5   # later targets may still be answered
        with self.lock:
            lat = [d for t, d in self.latencies if since <= t < until]
            sent = [t for t in self.sent.values() if since <= t < until]
            err = [e for t, e in self.errors if t >= since]
            self.latencies = [(t, d) for t, d in self.latencies if t >= since - 60.0]
        # (a burst of 10,000 targets is answered by its newest: the latest-only rule)
        return {'lat': np.array(lat), 'sent': len(sent), 'err': np.array(err)}

    def error_median(self, t0: float, t1: float) -> float:
        with self.lock:
            e = [v for t, v in self.errors if t0 <= t < t1]
        return float(np.median(e)) if e else math.nan


# ------------------------------------------------------------------ the soak
class Soak:
    """The processes, the client, the target stream, the faults and the samples."""

    def __init__(self, args) -> None:
        """Start the nodes and the client; wait until the loop runs."""
        self.args = args
        self.domain = random.randint(1, 101)
        self.env = child_env(self.domain)
        self.logs = Path(tempfile.mkdtemp(prefix='bellow_ancf_soak_'))
        self.cfg = load_robot('one_segment')
        self.procs = {}
        self._start('robot')
        self._start('inverse')
        self._start('forward')
        self.client = SoakClient(self.domain, self.cfg)
        t = np.arange(0.0, 20.0, 0.01)
        self.path = np.asarray(trajectory('planar_circle', t, self.cfg)[0])
        self.k = 0
        self.stream_on = threading.Event()
        self.stream_on.set()
        self.stop = threading.Event()
        self.robot_file = 'one_segment'
        self.robot_copy = self.logs / 'one_segment_copy.yaml'
        self.robot_copy.write_text(Path(find_shipped('one_segment')).read_text())
        self.records = []     # (fault, start, end, recovery s or None)
        if not wait_until(lambda: self.client.change_state.service_is_ready()
                          and self.client.pub_target.get_subscription_count() > 0, 60.0):
            raise RuntimeError('the inverse node did not come up; logs in ' + str(self.logs))
        self.streamer = threading.Thread(target=self._stream, daemon=True)
        self.streamer.start()

    def _start(self, which: str) -> None:
        if which == 'robot':
            self.procs[which] = NodeProcess('simulated_robot_node', {
                'robot_config': 'one_segment_mismatched', 'seed': 7}, self.env, self.logs,
                tag=f'{len(self.procs)}_')
        elif which == 'inverse':
            self.procs[which] = NodeProcess('inverse_kinetostatic_node', {
                'robot_config': 'one_segment', 'feedback': 'integral'}, self.env, self.logs)
        else:
            self.procs[which] = NodeProcess('forward_kinetostatic_node', {
                'robot_config': 'one_segment', 'max_rate_hz': 20.0}, self.env, self.logs,
                remaps={'pressure_command': 'measured_pressure'})

    def _stream(self) -> None:
        """100 Hz targets along the circle while ``stream_on``."""
        t_next = time.monotonic()
        while not self.stop.is_set():
            t_next += 0.01
            time.sleep(max(0.0, t_next - time.monotonic()))
            if self.stream_on.is_set():
                self.client.send_target(self.path[self.k % len(self.path)])
                self.k += 1

    # ------------------------------------------------------------ faults
    def fault(self, name: str) -> None:
        c = self.client
        if name == 'sim_kill':
            p = self.procs['robot'].proc
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(5.0)
            time.sleep(1.0)
            self._start('robot')
        elif name in ('stop_inverse', 'stop_forward'):
            pid = self.procs[name.split('_')[1]].proc.pid
            os.killpg(pid, signal.SIGSTOP)
            time.sleep(1.0)
            os.killpg(pid, signal.SIGCONT)
        elif name == 'burst':
            p = self.path[self.k % len(self.path)]
            self.stream_on.clear()
            for _ in range(10000):
                c.send_target(p)
            self.stream_on.set()
        elif name == 'bad_input':
            p = self.path[self.k % len(self.path)]
            for bad in ([math.nan, 0, 0.1], [math.inf, 0, 0.1]):
                for _ in range(10):
                    c.pub_target.publish(c.pose(bad))
                    c.pub_meas.publish(c.pose(bad))
            for _ in range(10):
                c.pub_target.publish(c.pose(p, frame='world'))
                c.pub_meas.publish(c.pose(p, frame='world'))
        elif name == 'payload':
            c.set_parameter('payload_kg', 0.05)
            time.sleep(5.0)
            c.set_parameter('payload_kg', 0.0)
        elif name == 'lifecycle':
            for _ in range(5):
                v0 = c.vents
                c.transition('deactivate')
                wait_until(lambda: c.vents > v0, 5.0)
                c.transition('activate')
        elif name == 'robot_switch':
            # to a copy of the same robot file and back: a switch that keeps the solve cost
            self.robot_file = (str(self.robot_copy) if self.robot_file == 'one_segment'
                               else 'one_segment')
            c.transition('deactivate')
            c.transition('cleanup')
            c.set_parameter('robot_config', self.robot_file)
            c.transition('configure')
            c.transition('activate')

    def recovery(self, start: float, end: float) -> float | None:
        """Seconds after ``end`` until the tracking error is back (None: not within 10 s)."""
        before = self.client.error_median(start - 10.0, start)
        limit = RECOVERY_FACTOR * before + RECOVERY_SLACK_M
        t = end
        deadline = end + 10.0
        while time.monotonic() < deadline:
            time.sleep(0.1)
            now = time.monotonic()
            if now - 0.5 >= t and self.client.error_median(now - 0.5, now) <= limit:
                return max(0.0, now - end - 0.5)
        return None

    # ------------------------------------------------------------ configure cycles
    def configure_cycles(self, n: int) -> list:
        c, pid = self.client, self.procs['inverse'].proc.pid
        rss = []
        self.stream_on.clear()
        for _ in range(n):
            for label in ('deactivate', 'cleanup', 'configure', 'activate'):
                if not c.transition(label):
                    raise RuntimeError(f'{label} refused during the configure cycles')
            rss.append(proc_stats(pid)['rss_mib'])
        self.stream_on.set()
        return rss

    def close(self) -> None:
        self.stop.set()
        self.streamer.join(2.0)
        self.client.close()
        for p in self.procs.values():
            p.stop()


def _fit_growth(ts, values):
    """Least-squares slope [per minute] of ``values`` over times ``ts`` [s]."""
    ts, values = np.asarray(ts, float), np.asarray(values, float)
    ok = np.isfinite(values)
    if ok.sum() < 3:
        return math.nan
    return float(np.polyfit(ts[ok] / 60.0, values[ok], 1)[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--minutes', type=float, default=10.0, help='duration of the soak')
    ap.add_argument('--sample-s', type=float, default=30.0, help='sampling period')
    ap.add_argument('--configure-cycles', type=int, default=50)
    ap.add_argument('--configure-only', action='store_true', help='only the configure cycles')
    args = ap.parse_args(argv)
    from bellow_ancf_ros.core import limit_blas_threads
    limit_blas_threads()

    soak = Soak(args)
    ok = True
    try:
        print(f'soak: {args.minutes:g} min, domain {soak.domain}, logs in {soak.logs}')
        time.sleep(5.0)
        rss = soak.configure_cycles(args.configure_cycles)
        # the first cycles grow RSS to a plateau (measured: +4.6 MiB over 20 cycles, then
        # +0.2 MiB over the next 100; allocator and middleware pools): judged after them
        first = SETTLE_CYCLES if len(rss) >= 2 * SETTLE_CYCLES else 0
        grew = rss[-1] - rss[first]
        print(f'configure cycles: {len(rss)}; inverse RSS {rss[0]:.1f} -> {rss[-1]:.1f} MiB, '
              f'{grew:+.2f} MiB from cycle {first + 1} to {len(rss)} (limit 2 MiB)')
        print('  RSS every 5th cycle [MiB]: ' + ' '.join(f'{v:.1f}' for v in rss[::5]))
        ok &= grew < 2.0
        if args.configure_only:
            return 0 if ok else 1

        t0 = time.monotonic()
        end = t0 + 60.0 * args.minutes
        samples, prev_cpu = [], {}
        header = (f"{'t_s':>6} " + ' '.join(f'{k + " MiB":>13} {"cpu%":>5} {"thr":>4} {"fd":>4}'
                                            for k in soak.procs)
                  + f" {'lat p50':>8} {'p99':>7} {'answered':>8} {'err mm':>7} {'bad':>4} faults")
        print(header)
        next_sample, next_fault, k_fault = t0 + args.sample_s, t0 + 20.0, 0
        window_start, faults_in_window = t0, []
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_fault and now < end - 25.0:
                name = FAULTS[k_fault % len(FAULTS)]
                k_fault += 1
                s = time.monotonic()
                try:
                    soak.fault(name)
                except RuntimeError as exc:
                    print(f'  fault {name} failed: {exc}')
                    ok = False
                e = time.monotonic()
                soak.records.append((name, s - t0, e - t0, soak.recovery(s, e)))
                faults_in_window.append(name)
                next_fault = time.monotonic() + args.sample_s
            if time.monotonic() >= next_sample:
                w = soak.client.window(window_start)
                row = {'t': time.monotonic() - t0}
                cells = []
                for k, p in soak.procs.items():
                    st = proc_stats(p.proc.pid)
                    dt = time.monotonic() - prev_cpu.get(k, (window_start, 0.0))[0]
                    cpu = (100.0 * (st['cpu_s'] - prev_cpu[k][1]) / dt
                           if k in prev_cpu and prev_cpu[k][2] == p.proc.pid else math.nan)
                    prev_cpu[k] = (time.monotonic(), st['cpu_s'], p.proc.pid)
                    row[k] = dict(st, cpu=cpu, pid=p.proc.pid)
                    cells.append(f"{st['rss_mib']:13.1f} {cpu:5.0f} {st['threads']:4d} "
                                 f"{st['fds']:4d}")
                lat, err = w['lat'], w['err']
                row['lat'] = lat
                row['answered'] = lat.size / max(w['sent'], 1)
                print(f"{row['t']:6.0f} " + ' '.join(cells)
                      + f" {np.median(lat) * 1e3 if lat.size else math.nan:6.2f}ms"
                      f" {np.percentile(lat, 99) * 1e3 if lat.size else math.nan:5.1f}ms"
                      f" {row['answered'] * 100:7.1f}%"
                      f" {np.median(err) * 1e3 if err.size else math.nan:7.3f}"
                      f" {soak.client.bad:4d} {','.join(faults_in_window)}", flush=True)
                samples.append(row)
                window_start, faults_in_window = time.monotonic(), []
                next_sample += args.sample_s
            for k, p in soak.procs.items():
                if not p.alive():
                    print(f'  {k} died (exit {p.proc.returncode}); log: {p.log_path}')
                    ok = False
                    soak._start(k)
            time.sleep(0.05)
    finally:
        soak.close()

    # ------------------------------------------------------------ summary
    print('\nsummary')
    for k in ('inverse', 'forward', 'robot'):
        # growth within each process's life (the robot is restarted by the faults), the
        # first sample of each life left out (start-up); lives of 3 samples or more
        lives = {}
        for r in samples:
            if k in r:
                lives.setdefault(r[k]['pid'], []).append(r)
        lives = [rows[1:] for rows in lives.values() if len(rows) >= 4]
        n = sum(len(rows) for rows in lives)
        fit = {q: (sum(_fit_growth([r['t'] for r in rows], [r[k][q] for r in rows]) * len(rows)
                       for rows in lives) / n if n else math.nan)
               for q in ('rss_mib', 'threads', 'fds')}
        g, th, fd = fit['rss_mib'], fit['threads'], fit['fds']
        grows = not (math.isnan(g) or g < GROWTH_LIMIT_MIB_PER_MIN) or th > 0.5 or fd > 0.5
        ok &= not grows
        print(f'  {k:8s} RSS {g:+.3f} MiB/min, threads {th:+.2f}/min, fds {fd:+.2f}/min over '
              f'{n} samples in {len(lives)} process(es){"  GROWS" if grows else ""}')
    third = max(1, len(samples) // 3)
    for label, part in (('early', samples[:third]), ('late', samples[-third:])):
        lat = np.concatenate([r['lat'] for r in part if r['lat'].size] or [np.zeros(0)])
        if lat.size:
            print(f'  latency {label:5s}: median {np.median(lat) * 1e3:.2f} ms, '
                  f'p90 {np.percentile(lat, 90) * 1e3:.2f} ms, p99 '
                  f'{np.percentile(lat, 99) * 1e3:.2f} ms ({lat.size} answers)')
    print(f'  commands {soak.client.commands}, bad outputs {soak.client.bad}'
          + (f' e.g. {soak.client.bad_examples}' if soak.client.bad else ''))
    ok &= soak.client.bad == 0
    for name, s, e, rec in soak.records:
        print(f'  fault {name:13s} at {s:6.1f} s ({e - s:5.1f} s): recovered '
              + ('NOT within 10 s' if rec is None else f'in {rec:.2f} s'))
        ok &= rec is not None
    print(f"verdict: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
