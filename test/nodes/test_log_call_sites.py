"""Every log call of the nodes has one severity: rclpy refuses a second at the same call site.

rclpy keeps a context per call site and raises ``ValueError: Logger
severity cannot be changed between calls`` when one logs at another
severity later.  The inverse node chose error or warning at one call site
for a solve's outcome: a warning (a budget-limited solve) and then an error
(a payload beyond buckling) made every later solve a "solver exception"
(``test_payload_beyond_buckling_names_the_cause_sends_nothing_and_does_not_wind_up``
failed so, once).
"""

import ast
from pathlib import Path

import pytest

NODES = Path(__file__).resolve().parents[2] / 'bellow_ancf_ros' / 'nodes'
LEVELS = {'debug', 'info', 'warn', 'warning', 'error', 'fatal'}


def _chosen_severity(tree) -> list:
    """Lines of the calls whose callee picks a level at run time: ``(log.a if c else log.b)()``."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.IfExp):
            branches = (node.func.body, node.func.orelse)
            if any(isinstance(b, ast.Attribute) and b.attr in LEVELS for b in branches):
                found.append(node.lineno)
    return found


@pytest.mark.parametrize('path', sorted(NODES.glob('*.py')), ids=lambda p: p.name)
def test_no_log_call_site_picks_its_severity(path):
    assert _chosen_severity(ast.parse(path.read_text())) == []


def test_the_check_finds_a_call_site_that_picks_its_severity():
    src = 'def f(log, ok):\n    (log.info if ok else log.warning)("x")\n'
    assert _chosen_severity(ast.parse(src)) == [2]
