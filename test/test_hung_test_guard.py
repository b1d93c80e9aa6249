"""hung_test_guard: a hung test ends its process with the stacks, and the run goes on or fails."""

import os
from pathlib import Path
import subprocess
import sys
import time

import pytest

SUPPORT = Path(__file__).resolve().parent / 'support'

HANGS = '''
import time


def test_before():
    pass


def test_hangs_in_a_sleep():
    time.sleep(120)


def test_after():
    pass
'''


def _run(tmp_path, *args, tests=HANGS):
    """Run ``tests`` under pytest, only the guard as plugin, 2 s limits; (status, output, s)."""
    (tmp_path / 'test_hangs.py').write_text(tests)
    env = dict(os.environ, BELLOW_HUNG_TEST_S='2', BELLOW_HUNG_EXIT_S='2',
               PYTHONPATH=str(SUPPORT) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    t0 = time.monotonic()
    res = subprocess.run([sys.executable, '-m', 'pytest', '-p', 'hung_test_guard', '-q',
                          '-p', 'no:cacheprovider', '-c', os.devnull, '--rootdir', str(tmp_path),
                          *args, str(tmp_path / 'test_hangs.py')],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=100)
    return res.returncode, res.stdout + res.stderr, time.monotonic() - t0


def test_without_workers_the_run_ends_with_the_hung_tests_stack(tmp_path):
    status, out, seconds = _run(tmp_path)
    assert status != 0 and seconds < 60, out
    assert 'Timeout (0:00:02)!' in out
    assert 'in test_hangs_in_a_sleep' in out      # the hung test's frame among the stacks
    assert 'passed' not in out                  # (the run ended there: no summary)


def test_under_xdist_the_worker_ends_and_the_other_tests_still_run(tmp_path):
    pytest.importorskip('xdist')
    status, out, seconds = _run(tmp_path, '-n', '1')
    assert status == 1 and seconds < 60, out
    assert 'in test_hangs_in_a_sleep' in out
    assert "crashed while running 'test_hangs.py::test_hangs_in_a_sleep'" in out
    assert '1 failed, 2 passed' in out


def test_a_process_that_hangs_after_its_run_ends_with_the_stacks(tmp_path):
    hangs_at_exit = ('import atexit, time\natexit.register(time.sleep, 120)\n\n\n'
                     'def test_ok():\n    pass\n')
    status, out, seconds = _run(tmp_path, tests=hangs_at_exit)
    assert status != 0 and seconds < 60, out
    assert '1 passed' in out and 'Timeout (0:00:02)!' in out


def test_the_suite_runs_with_every_hook_of_the_guard(request):
    import hung_test_guard
    for name in ('pytest_configure', 'pytest_runtest_protocol', 'pytest_unconfigure'):
        impls = getattr(request.config.pluginmanager.hook, name).get_hookimpls()
        assert any(i.function is getattr(hung_test_guard, name) for i in impls), name
