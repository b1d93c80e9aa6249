"""core.numba_cache: one cache directory per version of the compiled sources."""

import shutil

import numba

from bellow_ancf_ros.core import numba_cache


def test_the_tag_follows_the_compiled_modules_only(tmp_path):
    core = tmp_path / "core"
    shutil.copytree(numba_cache._CORE, core, ignore=shutil.ignore_patterns("__pycache__"))
    tag = numba_cache.source_tag(core)
    assert tag == numba_cache.source_tag(numba_cache._CORE)
    (core / "config.py").write_text((core / "config.py").read_text() + "\n# a comment\n")
    assert numba_cache.source_tag(core) == tag  # no compiled function in config.py
    (core / "ldlt.py").write_text((core / "ldlt.py").read_text() + "\n# a comment\n")
    assert numba_cache.source_tag(core) != tag  # chord.py's cached loop calls into ldlt.py


def test_numba_caches_in_the_tagged_directory(tmp_path):
    assert numba.config.CACHE_DIR == str(numba_cache.CACHE_DIR)
    assert numba_cache.CACHE_DIR.name == numba_cache.source_tag()
    env = {"NUMBA_CACHE_DIR": str(tmp_path)}
    assert numba_cache.cache_dir(env) == tmp_path / "bellow_ancf_ros" / numba_cache.source_tag()
