"""The house's rules, read from the source with ``ast`` (function-local imports included).

* no import cycle between the package's modules;
* ``core`` imports no rclpy, ``nodes``, ``cli`` or ``demos``;
* inside ``core``, subpackages import only downwards (:data:`CORE_LAYERS`) and
  another subpackage only through its ``__init__`` (its public names);
* outside ``core`` (nodes, CLI, demos, benchmarks, the Makefile), no private
  module and no private name of the package is imported;
* no module imports another module's private name (``from x import _y``).

Tests may import private modules: they test the internals.
"""

import ast
from pathlib import Path
import re

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / 'bellow_ancf_ros'
NAME = 'bellow_ancf_ros'

#: Rank of each part of core: a module may import parts of lower rank and its own part only.
CORE_LAYERS = {'status': 0, 'geometry': 0, 'history': 0, 'numba_cache': 0, 'linalg': 1,
               'model': 2, 'solve': 3, 'experiments': 4, 'dynamics': 4, 'sim': 5, 'control': 5,
               'loop': 6, 'fit': 6}


def module_name(path: Path) -> str:
    """Dotted name of a source file under the repository (``__init__`` -> its package)."""
    parts = list(path.relative_to(REPO).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts = parts[:-1]
    return '.'.join(parts)


def package_modules():
    """``{dotted name: path}`` of every module of the package."""
    return {module_name(p): p for p in sorted(PKG.rglob('*.py')) if '__pycache__' not in p.parts}


def imports_of(path: Path, modules=None):
    """Every import of ``path`` as ``(target module, imported name or None, line)``.

    Relative imports are resolved; ``from pkg import name`` names a module
    when ``pkg.name`` is one (``modules``), else a name of ``pkg``.
    """
    modules = modules if modules is not None else {}
    me = module_name(path)
    package = me if path.name == '__init__.py' else me.rpartition('.')[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, None, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')
                base = base[:len(base) - (node.level - 1)]
                target = '.'.join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for a in node.names:
                sub = f'{target}.{a.name}'
                if sub in modules:
                    out.append((sub, None, node.lineno))
                else:
                    out.append((target, a.name, node.lineno))
    return out


def _graph():
    modules = package_modules()
    graph = {m: set() for m in modules}
    for m, path in modules.items():
        for target, _, _ in imports_of(path, modules):
            if target in modules and target != m:
                graph[m].add(target)
    return graph


def find_cycle(graph):
    """One import cycle as a list of modules, or None."""
    state, stack = {}, []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state:
                cyc = visit(n)
                if cyc:
                    return cyc
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            cyc = visit(m)
            if cyc:
                return cyc
    return None


def test_find_cycle_finds_one():
    assert find_cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert find_cycle({'a': {'b'}, 'b': set()}) is None


def test_no_import_cycle():
    cycle = find_cycle(_graph())
    assert cycle is None, ' -> '.join(cycle)


def test_core_imports_no_ros_nodes_cli_or_demos():
    modules = package_modules()
    bad = []
    for m, path in modules.items():
        if not m.startswith(f'{NAME}.core'):
            continue
        for target, _, line in imports_of(path, modules):
            top = target.split('.')
            if top[0] in ('rclpy', 'launch', 'launch_ros') or (
                    top[0] == NAME and len(top) > 1 and top[1] in ('nodes', 'cli', 'demos')):
                bad.append(f'{path.relative_to(REPO)}:{line}: {target}')
    assert not bad, '\n'.join(bad)


def _core_part(dotted):
    parts = dotted.split('.')
    return parts[2] if len(parts) > 2 and parts[:2] == [NAME, 'core'] else None


def test_core_imports_only_downwards_and_through_public_names():
    modules = package_modules()
    bad = []
    for m, path in modules.items():
        mine = _core_part(m)
        if mine is None:
            continue
        for target, name, line in imports_of(path, modules):
            theirs = _core_part(target)
            if theirs is None or theirs == mine:
                continue
            where = f'{path.relative_to(REPO)}:{line}: {target}'
            if CORE_LAYERS[theirs] >= CORE_LAYERS[mine] and not m.endswith('.core'):
                bad.append(f'{where} ({mine} may not import {theirs})')
            if any(p.startswith('_') for p in target.split('.')):
                bad.append(f'{where} (another subpackage\'s private module)')
    assert not bad, '\n'.join(bad)


def _private(target, name):
    parts = target.split('.') + ([name] if name else [])
    return [p for p in parts if p.startswith('_') and not p.startswith('__')]


def test_nothing_outside_core_imports_private_modules_or_names():
    modules = package_modules()
    sources = [p for m, p in modules.items() if not m.startswith(f'{NAME}.core')]
    sources += sorted((REPO / 'bench').glob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
    bad = []
    for path in sources:
        for target, name, line in imports_of(path, modules):
            if target.split('.')[0] != NAME and not target.startswith('.'):
                continue
            if _private(target, name):
                bad.append(f'{path.relative_to(REPO)}:{line}: {target} {name or ""}')
    # the Makefile's inline Python too
    for line in (REPO / 'Makefile').read_text().splitlines():
        for ref in re.findall(rf'{NAME}(?:\.\w+)+', line):
            if any(p.startswith('_') for p in ref.split('.')):
                bad.append(f'Makefile: {ref}')
    assert not bad, '\n'.join(bad)


def test_no_module_imports_another_modules_private_name():
    modules = package_modules()
    bad = []
    for m, path in modules.items():
        for target, name, line in imports_of(path, modules):
            if name and name.startswith('_') and not name.startswith('__') \
                    and target.split('.')[0] == NAME:
                bad.append(f'{path.relative_to(REPO)}:{line}: from {target} import {name}')
    assert not bad, '\n'.join(bad)


def test_package_top_level_holds_only_init_and_subpackages():
    stray = [p.name for p in PKG.glob('*.py') if p.name != '__init__.py']
    assert not stray, stray
    assert len([p for p in (PKG / 'core').glob('*.py') if p.name != '__init__.py']) <= 4


@pytest.mark.parametrize('sub', sorted(k for k in CORE_LAYERS if (PKG / 'core' / k).is_dir()))
def test_each_core_subpackage_exports_what_its_all_names(sub):
    import importlib

    mod = importlib.import_module(f'{NAME}.core.{sub}')
    assert mod.__all__, sub
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, missing


def test_the_public_surface_has_what_users_and_nodes_need():
    import bellow_ancf_ros.core as core

    for name in ('load_robot', 'RobotModel', 'solve_forward', 'solve_inverse', 'warm_up',
                 'precompute_corners', 'limit_blas_threads', 'ForwardStatus', 'InverseStatus',
                 'geometry', 'ConfigError'):
        assert name in core.__all__ and hasattr(core, name), name


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` (a module, or a module's attribute path) names something real."""
    import importlib

    parts = dotted.split('.')
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:i]))
        except ImportError:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return False
        return True
    return False


def test_docstring_references_and_cited_paths_exist():
    """``:mod:`core.x```, ``bellow_ancf_ros.x.y`` and ``bellow_ancf_ros/x.py`` in the sources.

    Cross-references in docstrings and paths in comments (robot files
    included) name modules, objects and files that exist.
    """
    role = re.compile(r':(?:mod|func|class|meth|data|attr):`~?((?:core|bellow_ancf_ros)[\w.]*)`')
    dotted = re.compile(r'\bbellow_ancf_ros(?:\.\w+)+')
    path = re.compile(r'(?<![\w/])bellow_ancf_ros/[\w/]+\.(?:py|yaml)\b')  # not share/...
    files = [p for p in PKG.rglob('*.py') if '__pycache__' not in p.parts]
    files += sorted((REPO / 'config').glob('*.yaml')) + sorted((REPO / 'launch').glob('*.py'))
    bad = []
    for f in files:
        text = f.read_text()
        names = {m if m.startswith(NAME) else f'{NAME}.{m}' for m in role.findall(text)}
        names |= {m for m in dotted.findall(text) if not m.endswith('.py')}
        for name in sorted(names):
            if not _resolves(name.rstrip('.')):
                bad.append(f'{f.relative_to(REPO)}: {name}')
        for p in sorted(set(path.findall(text))):
            if not (REPO / p).exists():
                bad.append(f'{f.relative_to(REPO)}: {p}')
    assert not bad, '\n'.join(bad)
