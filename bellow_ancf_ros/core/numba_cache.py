"""Where the compiled kernels are cached: one directory per version of the compiled sources.

numba drops a function's cached machine code when the function's own source
file changes, but not when a compiled function it calls from another module
does (a documented limitation of its cache).  The chord loop
(``chord.py``) compiles in the residual kernel (``kernels.py``) and the
LDL^T solve (``ldlt.py``): after an update of ``ldlt.py`` alone, its cached
code would still run the old solve on the new memory layout, and crash.

:func:`configure` (run when this module is imported, which
``core/__init__.py`` does before anything else) therefore points numba's
cache at a directory named by a hash of every core module that defines
compiled functions: any change to one of them means a fresh compilation of
all, once.  The directory is
``core/__pycache__/numba-<hash>`` when the package directory is writable,
else ``$XDG_CACHE_HOME/bellow_ancf_ros/numba-<hash>`` (``~/.cache`` by
default), or under ``$NUMBA_CACHE_DIR`` when that is set.  Directories of
other hashes beside it are removed (best effort).
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

__all__ = ["configure", "cache_dir", "source_tag", "CACHE_DIR"]

_CORE = Path(__file__).resolve().parent


def source_tag(core: Path = _CORE) -> str:
    """``numba-`` and a hash of the modules in ``core`` that define compiled functions."""
    h = hashlib.sha256()
    for path in sorted(Path(core).glob("*.py")):
        data = path.read_bytes()
        if b"@njit" in data:
            h.update(path.name.encode() + b"\0" + data + b"\0")
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


CACHE_DIR = configure()
