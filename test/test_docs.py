"""The documentation points at things that exist: README.md and the pages of docs/.

* every repository path they cite (``bellow_ancf_ros/...``, ``config/...``,
  ``test/...``, ``bench/...``, ``docs/...``, ``launch/...``, ``data/...``,
  ``rviz/...``, and ``core/...``, ``nodes/...``, ``cli/...``, ``demos/...``
  inside the package; a ``test/...py::name`` citation also names a function
  of that file) exists, except the ``*.png`` files the demos and commands
  write;
* every dotted module name ``bellow_ancf_ros.x.y`` (and attribute after it)
  imports;
* every relative link goes to an existing file, and its ``#anchor`` to a
  heading of that file;
* the README is the front door: at most ``README_MAX_LINES`` lines, and it
  links every page of ``docs/``.

Paths under a user's own install or workspace (``share/bellow_ancf_ros/...``,
``~/ros2_ws/src/...``, ``$(ros2 pkg prefix ...)/...``) follow a ``/`` and are
not repository paths.
"""

import importlib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / 'README.md'
PAGES = sorted((REPO / 'docs').glob('*.md'))
DOCUMENTS = [README, *PAGES]
README_MAX_LINES = 220
TOP_DIRS = ('bellow_ancf_ros', 'config', 'test', 'bench', 'docs', 'launch', 'data', 'rviz')
#: the package's own folders, also cited without ``bellow_ancf_ros/`` (``core/numba_cache.py``)
PACKAGE_DIRS = ('core', 'nodes', 'cli', 'demos')

# a top directory not preceded by a path or word character, then path characters
PATH = re.compile(r'(?<![\w./$~-])((?:%s)/[\w./*-]*)(::\w+)?'
                  % '|'.join(TOP_DIRS + PACKAGE_DIRS))
MODULE = re.compile(r'(?<![\w./-])bellow_ancf_ros(?:\.\w+)+')
LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')


def cited_paths(text):
    """``(path, test name or None)`` of every repository path cited in ``text``."""
    out = []
    for m in PATH.finditer(text):
        path = m.group(1).rstrip('.,;:')
        if path.endswith('.png'):
            continue
        if path.startswith(PACKAGE_DIRS):
            path = 'bellow_ancf_ros/' + path
        out.append((path, m.group(2)[2:] if m.group(2) else None))
    return out


def missing_paths(text):
    """The cited paths (and ``file::test`` names) of ``text`` that do not exist."""
    missing = []
    for path, name in cited_paths(text):
        hits = list(REPO.glob(path)) if '*' in path else [REPO / path]
        if not hits or not all(p.exists() for p in hits):
            missing.append(path)
        elif name and not re.search(rf'^def {name}\(', hits[0].read_text(), re.M):
            missing.append(f'{path}::{name}')
    return missing


def slug(heading):
    """Anchor of a markdown heading, as GitHub makes it."""
    text = re.sub(r'[^\w\- ]', '', heading.strip().lower())
    return text.replace(' ', '-')


def anchors(path):
    """The anchors of every heading of a markdown file."""
    return {slug(h) for h in re.findall(r'^#+ (.+)$', path.read_text(), re.M)}


@pytest.mark.parametrize('doc', DOCUMENTS, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_cited_repository_path_exists(doc):
    text = doc.read_text()
    assert cited_paths(text) or doc.name == 'README.md'
    assert not missing_paths(text), missing_paths(text)


@pytest.mark.parametrize('doc', DOCUMENTS, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_cited_module_imports(doc):
    bad = []
    for dotted in set(MODULE.findall(doc.read_text())):
        parts = dotted.split('.')
        for n in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module('.'.join(parts[:n]))
                break
            except ModuleNotFoundError:
                continue
        try:
            for attr in parts[n:]:
                obj = getattr(obj, attr)
        except AttributeError:
            bad.append(dotted)
    assert not bad, bad


@pytest.mark.parametrize('doc', DOCUMENTS, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(doc):
    bad = []
    for target in LINK.findall(doc.read_text()):
        if re.match(r'[a-z]+:', target):
            continue
        file, _, anchor = target.partition('#')
        path = (doc.parent / file).resolve() if file else doc
        if not path.exists():
            bad.append(target)
        elif anchor and path.suffix == '.md' and anchor not in anchors(path):
            bad.append(target)
    assert not bad, bad


def test_readme_is_a_front_door_that_links_every_page():
    text = README.read_text()
    assert len(text.splitlines()) <= README_MAX_LINES
    linked = {target.partition('#')[0] for target in LINK.findall(text)}
    pages = {t for t in linked if t.startswith('docs/')}
    assert pages, 'the README links no page of docs/'
    assert all((REPO / t).is_file() for t in pages), sorted(pages)
    assert {p.relative_to(REPO).as_posix() for p in PAGES} <= pages


def test_ros_md_names_every_launch_argument():
    """docs/ros.md's list of launch arguments is the launch file's, no more, no less."""
    launch = (REPO / 'launch' / 'bellow_ancf.launch.py').read_text()
    declared = set(re.findall(r"DeclareLaunchArgument\(\s*'(\w+)'", launch))
    assert {'sim', 'sim_plant', 'rviz'} <= declared
    text = (REPO / 'docs' / 'ros.md').read_text()
    listed = re.search(r'its arguments \((.*?)\) override', text, re.S).group(1)
    assert set(re.findall(r'`(\w+)`', listed)) == declared


def test_the_checks_find_what_is_wrong():
    """The path, link and heading checks do fail on a wrong citation."""
    text = ('see `bellow_ancf_ros/core/no_such_module.py`, `config/one_segment.yaml`, '
            '`nodes/common.py`, '
            '`test/core/solve/test_forward.py::no_such_test`, '
            '$(ros2 pkg prefix bellow_ancf_ros)/share/bellow_ancf_ros/config/x.yaml '
            'and writes `bench/out.png`.')
    assert [p for p, _ in cited_paths(text)] == [
        'bellow_ancf_ros/core/no_such_module.py', 'config/one_segment.yaml',
        'bellow_ancf_ros/nodes/common.py', 'test/core/solve/test_forward.py']
    assert missing_paths(text) == ['bellow_ancf_ros/core/no_such_module.py',
                                   'bellow_ancf_ros/nodes/common.py',
                                   'test/core/solve/test_forward.py::no_such_test']
    assert slug('## 5. The default robot'.lstrip('# ')) == '5-the-default-robot'
