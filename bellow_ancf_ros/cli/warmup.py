"""``bellow-ancf warm-up``: compile the numerical kernels now, not at a node's first start.

Registered by :func:`register` into the parser of :mod:`bellow_ancf_ros.cli`::

    bellow-ancf warm-up [--config C ...]

The first start after an installation compiles the kernels (about a minute on
a 2-core machine) into the cache of these sources
(:mod:`bellow_ancf_ros.core.numba_cache`); a lab runs this once after
``colcon build`` (``ros2 run bellow_ancf_ros bellow-ancf warm-up``) so that no
node pays it, nor several nodes of one launch at once.
"""

from __future__ import annotations

import time

from ..core import ConfigError, RobotModel, load_robot, numba_cache, warm_up
from ..core.dynamics import warm_up_dynamics
from .common import EXIT_OK, UsageError

__all__ = ['register']


def _cmd_warm_up(args) -> int:
    before = numba_cache.is_compiled()
    t0 = time.perf_counter()
    for name in args.config or ('one_segment', 'two_segment'):
        try:
            model = RobotModel(load_robot(name))
        except ConfigError as exc:
            raise UsageError(f'--config: {exc}') from None
        warm_up(model)
        warm_up_dynamics(model)   # the simulated robot's integrator
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
    p.set_defaults(func=_cmd_warm_up)
