"""The README's first lines and its Python example stay true."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_first_lines_are_the_two_fresh_machine_commands():
    lines = README.read_text().splitlines()
    assert lines[0].split("#")[0].strip() == "make demo"
    assert lines[1].split("#")[0].strip() == "make test"


def test_python_example_runs():
    text = README.read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    ns = {}
    exec(compile(code, str(README), "exec"), ns)  # noqa: S102 - our own documentation
    assert ns["fw"].success and ns["inv"].reachable
    assert np.linalg.norm(ns["inv"].forward.position - ns["fw"].position) < 1e-6
    assert ns["inv2"].success and ns["inv2"].reachable
    assert ns["shape"].shape == (3, 30, 3)
