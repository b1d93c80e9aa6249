"""flake8 as the ament_python template runs it (``ament_flake8``, max line length 99).

The paths are given explicitly (the template checks the current directory,
which here would include the virtual environment).
"""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO = Path(__file__).resolve().parents[1]
PATHS = ['bellow_ancf_ros', 'test', 'launch', 'bench', 'data', 'setup.py']


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, errors = main_with_errors(argv=[str(REPO / p) for p in PATHS])
    assert rc == 0, \
        'Found %d code style errors / warnings:\n' % len(errors) + \
        '\n'.join(errors)
