"""core.numba_cache: one cache directory per version of the compiled sources."""

import re
import shutil

import numba

from bellow_ancf_ros.core import numba_cache


def test_the_tag_follows_the_compiled_modules_only(tmp_path):
    core = tmp_path / "core"
    shutil.copytree(numba_cache._CORE, core, ignore=shutil.ignore_patterns("__pycache__"))
    tag = numba_cache.source_tag(core)
    assert tag == numba_cache.source_tag(numba_cache._CORE)
    config = core / "model" / "_config.py"
    config.write_text(config.read_text() + "\n# a comment\n")
    assert numba_cache.source_tag(core) == tag  # no compiled function in _config.py
    ldlt = core / "linalg" / "_ldlt.py"
    ldlt.write_text(ldlt.read_text() + "\n# a comment\n")
    assert numba_cache.source_tag(core) != tag  # _chord.py's cached loop calls into _ldlt.py


def test_every_module_with_compiled_functions_is_hashed(tmp_path):
    """Subpackages included: editing any module with @njit anywhere under core/ changes the tag."""
    core = tmp_path / "core"
    shutil.copytree(numba_cache._CORE, core, ignore=shutil.ignore_patterns("__pycache__"))
    compiled = [p for p in sorted(core.rglob("*.py"))
                if re.search(rb"^[ \t]*@njit", p.read_bytes(), re.M)]
    names = {p.relative_to(core).as_posix() for p in compiled}
    assert names == {"model/_kernels.py", "linalg/_ldlt.py", "solve/_chord.py",
                     "solve/_inverse_warm.py", "dynamics/_kernels.py"}
    assert {p.relative_to(numba_cache._CORE).as_posix()
            for p in numba_cache.compiled_modules()} == names
    for path in compiled:
        tag = numba_cache.source_tag(core)
        path.write_text(path.read_text() + "\n# edited\n")
        assert numba_cache.source_tag(core) != tag, path


def test_numba_caches_in_the_tagged_directory(tmp_path):
    assert numba.config.CACHE_DIR == str(numba_cache.CACHE_DIR)
    assert numba_cache.CACHE_DIR.name == numba_cache.source_tag()
    env = {"NUMBA_CACHE_DIR": str(tmp_path)}
    assert numba_cache.cache_dir(env) == tmp_path / "bellow_ancf_ros" / numba_cache.source_tag()


def test_is_compiled_after_a_warm_up():
    from bellow_ancf_ros.core import RobotModel, load_robot, warm_up
    for name in ("one_segment", "two_segment"):   # (the pseudo-inverse: redundant robots)
        warm_up(RobotModel(load_robot(name)))
    assert numba_cache.is_compiled()
