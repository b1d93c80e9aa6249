"""A ``ros2`` command for the tests: the two verbs the documentation runs on a colcon install.

``ros2cli`` is not on PyPI.  What the real tools do was measured with ROS 2
Jazzy (ros2cli 0.32.2) on a ROS install, and this does
exactly that, nothing more:

* ``ros2 run PKG EXE [ARGS ...]``: the first prefix ``P`` on
  ``AMENT_PREFIX_PATH`` that holds
  ``P/share/ament_index/resource_index/packages/PKG``, then the executable
  file ``P/lib/PKG/EXE`` of that same prefix, run with ``ARGS`` (exec, so the
  exit status and signals are the executable's);
* ``ros2 pkg prefix [--share] PKG``: prints ``P`` (``P/share/PKG`` with
  ``--share``).

Errors as ros2cli words them (``Package 'x' not found``, ``No executable
found``), exit status 1.  Any other verb exits 2 with ``not emulated``, so
that a test cannot pass through a command this shim does not do.
"""

import os
import sys


def prefix_of(package):
    """The first ``AMENT_PREFIX_PATH`` entry holding ``package``'s ament index marker, or None."""
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        marker = os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages',
                              package)
        if prefix and os.path.isfile(marker):
            return prefix
    return None


def _fail(message, code=1):
    print(message, file=sys.stderr)
    return code


def main(argv):
    if len(argv) >= 3 and argv[0] == 'run':
        package, executable, args = argv[1], argv[2], argv[3:]
        prefix = prefix_of(package)
        if prefix is None:
            return _fail(f"Package '{package}' not found")
        path = os.path.join(prefix, 'lib', package, executable)
        if not (os.path.isfile(path) and os.access(path, os.X_OK)):
            return _fail('No executable found')
        os.execv(path, [path, *args])
    if len(argv) >= 3 and argv[:2] == ['pkg', 'prefix']:
        share = '--share' in argv[2:]
        names = [a for a in argv[2:] if a != '--share']
        if len(names) != 1:
            return _fail('usage: ros2 pkg prefix [--share] package_name', 2)
        prefix = prefix_of(names[0])
        if prefix is None:
            return _fail('Package not found')
        print(os.path.join(prefix, 'share', names[0]) if share else prefix)
        return 0
    return _fail(f'ros2 (test shim): not emulated: {" ".join(argv)}', 2)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
