"""Docstring style as the ament_python template checks it (``ament_pep257``).

The project's convention (README, docs/model.md): PEP 257 with the summary
on the first line, imperative mood not required.  So the check is
pydocstyle's ``pep257`` convention, plus ament's ignores of missing
docstrings (D100-D107), plus D401 (imperative mood).
"""

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO = Path(__file__).resolve().parents[1]
PATHS = ['bellow_ancf_ros', 'test', 'launch', 'bench', 'data', 'setup.py']
IGNORE = ['D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107', 'D401']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=['--convention', 'pep257', '--add-ignore', *IGNORE, '--']
              + [str(REPO / p) for p in PATHS])
    assert rc == 0, 'Found code style errors / warnings'
