"""BLAS on one thread inside the core's solves, however they are called.

The core's dense linear algebra is small (a few hundred rows at most); a
multithreaded BLAS only adds overhead there, and on a loaded 2-core machine
it makes such calls ten to twenty times slower (a 2 ms Cholesky took 40 ms).
So the core's entry points (:func:`one_thread_call`) and its LAPACK calls
(:func:`one_thread`) limit BLAS to one thread themselves, and no caller has
to remember.  Entering costs about a microsecond: the BLAS libraries are
looked up once (threadpoolctl), and a nested or already single-threaded
context does nothing.  Without threadpoolctl it is a no-op.
"""

from __future__ import annotations

import functools
import threading

__all__ = ["one_thread", "one_thread_call", "limit_blas_threads"]

_LIBS = []  # [list of threadpoolctl library controllers] once looked up
_LOCK = threading.Lock()
_STATE = {"depth": 0, "saved": ()}


def _libraries():
    if not _LIBS:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # optional dependency
            _LIBS.append([])
        else:
            _LIBS.append(list(ThreadpoolController().select(user_api="blas").lib_controllers))
    return _LIBS[0]


class _OneThread:
    """Reentrant, thread-safe: the outermost context sets one thread and restores on exit."""

    __slots__ = ()

    def __enter__(self):
        with _LOCK:
            if _STATE["depth"] == 0:
                saved = []
                for lib in _libraries():
                    n = lib.get_num_threads()
                    if n != 1:
                        lib.set_num_threads(1)
                        saved.append((lib, n))
                _STATE["saved"] = tuple(saved)
            _STATE["depth"] += 1
        return self

    def __exit__(self, *exc):
        with _LOCK:
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0:
                for lib, n in _STATE["saved"]:
                    lib.set_num_threads(n)
                _STATE["saved"] = ()
        return False


_ONE = _OneThread()


def one_thread():
    """Context manager: BLAS on one thread inside (restored on leaving the outermost one)."""
    return _ONE


def one_thread_call(fun):
    """Decorate a core entry point: it runs with BLAS on one thread."""

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        with _ONE:
            return fun(*args, **kwargs)

    return wrapper


def limit_blas_threads(n=1):
    """Limit BLAS to ``n`` threads for the whole process (callers' own numpy work).

    Returns the threadpoolctl limiter (None without threadpoolctl).
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional dependency
        return None
    return threadpool_limits(limits=n, user_api="blas")
