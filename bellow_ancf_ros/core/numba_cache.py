"""Where the compiled kernels are cached: one directory per version of the compiled sources.

numba drops a function's cached machine code when the function's own source
file changes, but not when a compiled function it calls from another module
does (a documented limitation of its cache).  The chord loop
(``solve/_chord.py``) compiles in the residual kernel (``model/_kernels.py``)
and the LDL^T solve (``linalg/_ldlt.py``): after an update of ``_ldlt.py``
alone, its cached code would still run the old solve on the new memory
layout, and crash.

:func:`configure` (run when this module is imported, which
``core/__init__.py`` does before anything else) therefore points numba's
cache at a directory named by a hash of every core module that defines
compiled functions, in every subpackage (``core/**/*.py``): any change to
one of them means a fresh compilation of all, once.  The directory is
``core/__pycache__/numba-<hash>`` when the package directory is writable,
else ``$XDG_CACHE_HOME/bellow_ancf_ros/numba-<hash>`` (``~/.cache`` by
default), or under ``$NUMBA_CACHE_DIR`` when that is set.  Directories of
other hashes beside it are removed (best effort).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
from pathlib import Path

__all__ = ["configure", "cache_dir", "compiled_modules", "is_compiled", "source_tag", "CACHE_DIR"]

_CORE = Path(__file__).resolve().parent
_DECORATED = re.compile(rb"^[ \t]*@njit", re.M)   # a decorator line, not the word in a string


def compiled_modules(core: Path = _CORE) -> list[Path]:
    """The modules under ``core`` (subpackages included) that define compiled functions."""
    return [p for p in sorted(Path(core).rglob("*.py"))
            if "__pycache__" not in p.parts and _DECORATED.search(p.read_bytes())]


def source_tag(core: Path = _CORE) -> str:
    """``numba-`` and a hash of the modules under ``core`` (any depth) with compiled functions."""
    h = hashlib.sha256()
    for path in sorted(compiled_modules(core)):
        h.update(path.relative_to(core).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return "numba-" + h.hexdigest()[:16]


def cache_dir(environ=None) -> Path:
    """The cache directory for the current sources (see the module docstring)."""
    env = os.environ if environ is None else environ
    tag = source_tag()
    if env.get("NUMBA_CACHE_DIR"):
        return Path(env["NUMBA_CACHE_DIR"]) / "bellow_ancf_ros" / tag
    pycache = _CORE / "__pycache__"
    if os.access(_CORE, os.W_OK) and (not pycache.exists() or os.access(pycache, os.W_OK)):
        return pycache / tag
    xdg = env.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "bellow_ancf_ros" / tag


def configure() -> Path:
    """Point numba's cache at :func:`cache_dir`; returns it."""
    import numba

    root = cache_dir()
    for old in root.parent.glob("numba-*") if root.parent.is_dir() else ():
        if old.name != root.name:
            shutil.rmtree(old, ignore_errors=True)
    numba.config.CACHE_DIR = str(root)
    return root


def is_compiled() -> bool:
    """Whether the kernels of these sources are in the cache already (else: a first start).

    Looks for numba's index files of the three compiled modules in
    :data:`CACHE_DIR`; a first start after installation compiles them
    (about a minute on a 2-core machine), later starts load them.
    """
    if not CACHE_DIR.is_dir():
        return False
    stems = {p.stem for p in compiled_modules()}
    found = {f.name.split(".")[0] for f in CACHE_DIR.rglob("*.nbi")}
    return stems <= found


CACHE_DIR = configure()
