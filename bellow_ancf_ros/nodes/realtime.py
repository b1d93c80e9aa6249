"""A control node's threads on the real-time scheduler (parameter ``realtime_priority``).

On a computer that runs other work beside the controller (rviz2, a rosbag
recorder, a mocap driver, a build), the kernel's normal scheduler shares the
cores fairly: the inverse node's solver then waits for its turn behind
CPU-bound processes, its commands come late and irregular, and the irregular
staircase of pressures rings a lightly damped robot.  Measured with
``bench/busy_bench.py`` (two segments, the 10x circle, one CPU-bound process
per core): circle RMSE 0.53-6.51 mm over five runs on the normal scheduler,
0.61-0.84 mm over five runs with the inverse node's threads at SCHED_FIFO
priority 10, interleaved (docs/performance.md).

So the inverse node asks for ``SCHED_FIFO`` at :data:`REALTIME_PRIORITY` for
every thread of its process (the solver, the executor, the middleware's),
as ros2_control's controller manager does for its update loop: a CPU-bound
process at normal priority then waits for the controller, not the other way
round.  The priority stays below the kernel's threaded interrupts (50).  It
needs the privilege: root, ``CAP_SYS_NICE``, or an ``rtprio`` limit for the
user (``/etc/security/limits.conf``: ``@realtime - rtprio 98``, the user in
group ``realtime``, as ros2_control's documentation sets it up).  Without
it the node logs one warning and runs on the normal scheduler.  Under
``use_sim_time`` the simulation's lockstep times everything and the
scheduler is left alone.  A thread of background work (the first mode's
analysis) goes back to the normal scheduler itself (:func:`background`).
"""

from __future__ import annotations

import os
import threading

__all__ = ['REALTIME_PARAMETER', 'REALTIME_PRIORITY', 'background', 'use_realtime']

#: The parameter a node declares to be put on the real-time scheduler (:func:`use_realtime`).
REALTIME_PARAMETER = 'realtime_priority'
#: The SCHED_FIFO priority a control node asks for by default (1-98; 0: the normal scheduler).
REALTIME_PRIORITY = 10
#: The threads (native ids) that do a node's background work (:func:`background`).
_BACKGROUND: set = set()


def _threads() -> list[int]:
    """The thread ids of this process, but those of its background work."""
    try:
        return sorted(int(t) for t in os.listdir('/proc/self/task')
                      if int(t) not in _BACKGROUND)
    except OSError:
        return [0]


def use_realtime(node) -> str:
    """Put this process's threads at the node's ``realtime_priority``; what was done, in words.

    Threads started later inherit the policy of the thread that starts
    them; those of background work (:func:`background`) are left on the
    normal scheduler.  Logs one line: the priority taken, or why not (a warning).
    Nothing for a node without the parameter, at 0 or under ``use_sim_time``.
    """
    if not node.has_parameter(REALTIME_PARAMETER):
        return ''
    priority = int(node.get_parameter(REALTIME_PARAMETER).value)
    log = node.get_logger()
    if priority <= 0:
        return 'normal scheduler (realtime_priority 0)'
    if node.has_parameter('use_sim_time') and node.get_parameter('use_sim_time').value:
        return 'normal scheduler (use_sim_time: the lockstep times the loop)'
    if not hasattr(os, 'sched_setscheduler'):
        text = (f'realtime_priority {priority}: this system has no SCHED_FIFO; '
                'the normal scheduler')
        log.warning(text)
        return text
    threads = _threads()
    try:
        for tid in threads:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        for tid in threads:   # (all or none: the solver must not wait on a normal thread)
            try:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            except OSError:
                pass
        text = (f'realtime_priority {priority}: not permitted ({exc.strerror}); the normal '
                'scheduler, so a busy computer can delay the commands (grant an rtprio limit '
                'or CAP_SYS_NICE, or set realtime_priority 0 to silence this)')
        log.warning(text)
        return text
    text = f'scheduling: SCHED_FIFO priority {priority} for its {len(threads)} threads'
    log.info(text)
    return text


def background() -> None:
    """Put the calling thread on the normal scheduler: a node's background work.

    The inverse node's analysis of its first mode (``ModeWatch``, some
    100 ms of CPU at a time) is not on the command path; on SCHED_FIFO it
    would take a core from everything else on the machine, the motion
    capture driver and the regulators' side included.  A thread may always
    lower its own priority.
    """
    _BACKGROUND.add(threading.get_native_id())   # (use_realtime leaves it there)
    if hasattr(os, 'sched_setscheduler') and os.sched_getscheduler(0) != os.SCHED_OTHER:
        try:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass
