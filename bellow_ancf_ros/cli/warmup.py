"""``bellow-ancf warm-up``: compile the numerical kernels now, not at a node's first start.

Registered by :func:`register` into the parser of :mod:`bellow_ancf_ros.cli`::

    bellow-ancf warm-up [--config C ...] [--quiet]

The first start after an installation compiles the kernels (about a minute on
a 2-core machine) into the cache of these sources
(:mod:`bellow_ancf_ros.core.numba_cache`); a lab runs this once after
``colcon build`` (``ros2 run bellow_ancf_ros bellow-ancf warm-up``) so that no
node pays it, nor several nodes of one launch at once.  Progress on stderr
(``--quiet`` silences it): a line when each robot's kernel group starts, with
the time since the start, and one every :data:`HEARTBEAT_S` while it compiles.
"""

from __future__ import annotations

from functools import partial
import threading
import time

from ..core import ConfigError, RobotModel, load_robot, numba_cache, warm_up
from ..core.dynamics import warm_up_dynamics
from .common import EXIT_OK, UsageError, add_quiet, progress

__all__ = ['HEARTBEAT_S', 'register']

#: While a kernel group compiles, a progress line this often [s].
HEARTBEAT_S = 10.0


def _group(report, done: int, total: int, label: str, work):
    """``work()``, reporting its start and, every HEARTBEAT_S, that it still runs.

    ``label``: the robot, the kernel group and what is done (``compiling``
    or ``loading``).
    """
    if report is None:
        return work()
    report(done, total, label)
    finished = threading.Event()

    def beat() -> None:
        while not finished.wait(HEARTBEAT_S):
            report(done, total, f'{label}, still')
    ticker = threading.Thread(target=beat, name='warm-up progress', daemon=True)
    ticker.start()
    try:
        return work()
    finally:
        finished.set()
        ticker.join()


def _solver_kernels(cfg) -> RobotModel:
    model = RobotModel(cfg)   # (the model's set-up runs compiled kernels too: most of the time)
    warm_up(model)
    return model


def _cmd_warm_up(args) -> int:
    before = numba_cache.is_compiled()
    t0 = time.perf_counter()
    robots = []
    for name in args.config or ('one_segment', 'two_segment'):   # all read before compiling
        try:
            robots.append((name, load_robot(name)))
        except ConfigError as exc:
            raise UsageError(f'--config: {exc}') from None
    report, total = progress(args, 'warm-up'), 2 * len(robots)
    doing = 'loading' if before else 'compiling'
    for k, (name, cfg) in enumerate(robots):
        model = _group(report, 2 * k, total, f'{name}: {doing} the solver kernels',
                       partial(_solver_kernels, cfg))
        _group(report, 2 * k + 1, total, f'{name}: {doing} the dynamics kernel',
               partial(warm_up_dynamics, model))   # the simulated robot's integrator
    state = 'were compiled already (loaded)' if before else 'compiled'
    print(f'numerical kernels {state} in {time.perf_counter() - t0:.1f} s; cache: '
          f'{numba_cache.CACHE_DIR}', flush=True)
    return EXIT_OK


def register(subparsers) -> None:
    """Add the ``warm-up`` subcommand."""
    p = subparsers.add_parser(
        'warm-up', help='compile the numerical kernels now (once after installation)',
        description='Compile (or load) every numerical kernel the nodes use, so that no node '
                    'start pays the one-time compilation (about a minute on 2 cores).',
        epilog='Example: ros2 run bellow_ancf_ros bellow-ancf warm-up')
    p.add_argument('--config', nargs='+', action='extend', metavar='CFG',
                   help='robots to warm up (file paths or shipped names); default: '
                        'one_segment two_segment')
    add_quiet(p)
    p.set_defaults(func=_cmd_warm_up)
