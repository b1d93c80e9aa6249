"""A pytest plugin: a test still running after HUNG_TEST_S is taken as hung and ends its process.

A test that hangs would otherwise hold the suite until CI's own limit ends
everything with no word of where it stood (one run of the ROS phase stopped
at 141 of 163 tests for over an hour).  faulthandler's watchdog is a C
thread: it still fires when a C call holds the interpreter (freeing rclpy's
EventsExecutor did so in a node process), where a Python timer thread, as
pytest-timeout's thread method uses, cannot run.  It prints every thread's
stack on the stderr pytest started with (not the captured one) and ends the
process: under pytest-xdist the worker, which xdist reports as crashed in
that test before it goes on with a new worker; without xdist the run, with
a non-zero status.

The run's own end (the interpreter's finalisation, where rclpy's objects
are freed) gets ``HUNG_EXIT_S`` the same way.  ``BELLOW_HUNG_TEST_S`` and
``BELLOW_HUNG_EXIT_S`` in the environment set the limits [s] (tests of this
plugin use short ones).
"""

import faulthandler
import os

import pytest

#: Longer than any test of the suite on a busy 2-core machine (the longest, a main-job run in
#: the serial phase, takes a few minutes), far shorter than CI's limit for the whole run.
HUNG_TEST_S = float(os.environ.get('BELLOW_HUNG_TEST_S', '900'))
#: From the end of the run to the process's exit: the finalisation takes seconds.
HUNG_EXIT_S = float(os.environ.get('BELLOW_HUNG_EXIT_S', '120'))

_STDERR: list = []


def pytest_configure(config):
    """Keep the stderr the run started with: pytest's capture replaces descriptor 2 per test."""
    _STDERR.append(os.fdopen(os.dup(2), 'w'))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Arm the watchdog for one test (set-up, call and teardown); disarm it after."""
    faulthandler.dump_traceback_later(HUNG_TEST_S, exit=True, file=_STDERR[-1])
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


def pytest_unconfigure(config):
    """Arm the watchdog for the process's end (never disarmed: the exit ends it)."""
    faulthandler.dump_traceback_later(HUNG_EXIT_S, exit=True, file=_STDERR[-1])
