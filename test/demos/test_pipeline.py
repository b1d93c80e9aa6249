"""demos.pipeline: node processes that hang at start-up are seen, shown and restarted once."""

import sys
import time

from bellow_ancf_ros.demos import pipeline
from bellow_ancf_ros.demos.pipeline import NodeProcess, child_env, wait_up


def _hangs(mark):
    """Import the nodes package (SIGUSR1 dumps stacks), say so in ``mark``, hang silently."""
    return [sys.executable, '-c', 'import bellow_ancf_ros.nodes, pathlib, threading; '
            f'pathlib.Path({str(mark)!r}).touch(); threading.Event().wait()']


def _process(tmp_path, cmd):
    p = NodeProcess.__new__(NodeProcess)
    p.module, p.cmd, p.env, p.nice = 'hanging_node', cmd, child_env(0), 0
    p.log_path = tmp_path / 'hanging_node.log'
    p._start('w')
    return p


def test_silent_process_shows_its_stacks_and_is_restarted_once(tmp_path, capsys):
    mark = tmp_path / 'imported'
    p = _process(tmp_path, _hangs(mark))
    try:
        first = p.proc.pid
        assert pipeline.wait_until(mark.exists, 20.0) and p.silent()
        assert p.restart_if_silent()
        assert p.proc.pid != first and p.alive()
        log = p.log_path.read_text()
        assert 'most recent call first' in log      # faulthandler's dump of the hung run
        assert 'restarted after a hang at start-up' in log
        assert 'hanging_node restarted once' in capsys.readouterr().out
        # a process that wrote something is not silent: not restarted
        p.proc.kill()
        p.proc.wait()
        p.cmd = [sys.executable, '-c', 'print("up", flush=True); import time; time.sleep(60)']
        p._start('w')
        assert pipeline.wait_until(lambda: p.log_path.stat().st_size > 0, 5.0)
        assert not p.restart_if_silent()
    finally:
        p.stop(2.0)


def test_wait_up_restarts_a_silent_process_and_waits_again(tmp_path):
    p = _process(tmp_path, _hangs(tmp_path / 'imported'))
    try:
        t0 = time.monotonic()
        starts = []
        orig = p._start

        def start_and_count(mode):
            starts.append(mode)
            p.cmd = [sys.executable, '-c', 'print("up", flush=True); import time; time.sleep(60)']
            orig(mode)

        p._start = start_and_count
        assert wait_up([p], lambda: 'up\n' in p.log_path.read_text(), 3.0)
        assert starts == ['a'] and time.monotonic() - t0 < 15.0
        # nothing silent to restart: wait_up gives up after one wait
        assert not wait_up([p], lambda: False, 0.2)
        assert starts == ['a']
    finally:
        p.stop(2.0)


class _Proc:
    """Records in ``log`` when it was interrupted and when it was stopped."""

    def __init__(self, name, log):
        self.name, self.log = name, log

    def interrupt(self):
        self.log.append(('interrupt', self.name))

    def stop(self):
        self.log.append(('stop', self.name))
        return 0


def test_the_controller_stops_alone_before_the_others_so_its_vent_reaches_them():
    log = []
    procs = {k: _Proc(k, log) for k in ('robot', 'inverse', 'forward')}
    codes = pipeline.stop_all(procs)
    assert codes == {'inverse': 0, 'robot': 0, 'forward': 0}
    assert log[0] == ('stop', 'inverse')                  # exited (vented) first
    assert {e for e in log[1:3]} == {('interrupt', 'robot'), ('interrupt', 'forward')}
    assert [e for e in log[3:]] == [('stop', 'forward'), ('stop', 'robot')]


def test_a_recorder_waits_for_the_vent_its_callback_may_take_late():
    """``Recorder.wait_for_vent``: the newest command all zero, within the timeout."""
    import threading
    from types import SimpleNamespace

    def rec(*commands):
        return SimpleNamespace(lock=threading.Lock(), msgs={'pressure_command': [
            (0.0, SimpleNamespace(data=list(c))) for c in commands]})
    assert pipeline.Recorder.wait_for_vent(rec([10e3, 0.0, 5e3], [0.0, 0.0, 0.0]), timeout=0.1)
    assert not pipeline.Recorder.wait_for_vent(rec([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                                               timeout=0.1)
    assert not pipeline.Recorder.wait_for_vent(rec(), timeout=0.05)
    late = rec([20e3, 1e3, 0.0])
    t0 = time.monotonic()
    threading.Timer(0.2, lambda: late.msgs['pressure_command'].append(
        (0.3, SimpleNamespace(data=[0.0, 0.0, 0.0])))).start()
    assert pipeline.Recorder.wait_for_vent(late, timeout=5.0)
    assert 0.15 < time.monotonic() - t0 < 2.0


def test_the_node_processes_import_this_package(tmp_path):
    """The children's path starts with the directory holding the package imported here.

    (It held the package's own directory, where ``import bellow_ancf_ros``
    finds nothing: a demo run from another directory drove the installed copy.)
    """
    import os
    import subprocess
    from pathlib import Path

    import bellow_ancf_ros
    env = child_env(0)
    first = Path(env['PYTHONPATH'].split(os.pathsep)[0])
    assert (first / 'bellow_ancf_ros' / '__init__.py').exists()
    code = 'import bellow_ancf_ros; print(bellow_ancf_ros.__file__)'
    out = subprocess.run([sys.executable, '-c', code], env={**env, 'PYTHONPATH': str(first)},
                         cwd=tmp_path, capture_output=True, text=True, check=True).stdout.strip()
    assert Path(out).resolve() == Path(bellow_ancf_ros.__file__).resolve()


def test_group_nice_sets_the_niceness_of_a_sessions_scheduling_group(tmp_path):
    """With autogroups, a process's own niceness counts only inside its session."""
    import os
    import subprocess
    from pathlib import Path
    if not Path('/proc/self/autogroup').exists():
        assert not pipeline.group_nice(os.getpid(), 5)
        return
    child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'],
                             start_new_session=True)
    try:
        assert pipeline.group_nice(child.pid, 5)
        assert Path(f'/proc/{child.pid}/autogroup').read_text().split()[-1] == '5'
        assert Path('/proc/self/autogroup').read_text() != Path(
            f'/proc/{child.pid}/autogroup').read_text()   # (its own group; ours untouched)
    finally:
        child.kill()
        child.wait()
