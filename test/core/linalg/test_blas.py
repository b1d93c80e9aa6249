"""core.blas: the core's solves run BLAS on one thread, however they are called."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.linalg import _blas as blas
import bellow_ancf_ros.core.solve._forward as fwd


def test_solves_run_blas_on_one_thread_and_restore_it():
    threadpoolctl = pytest.importorskip("threadpoolctl")

    def blas_threads():
        info = threadpoolctl.threadpool_info()
        return {i["num_threads"] for i in info if i["user_api"] == "blas"}

    seen = []

    @blas.one_thread_call
    def solve(x):
        seen.append(blas_threads())
        with blas.one_thread():  # nested: still one thread, and the outer one restores
            seen.append(blas_threads())
        seen.append(blas_threads())
        return x

    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        outside = blas_threads()
        assert outside == {2}
        assert solve(1) == 1
        assert blas_threads() == outside  # restored
        # the core's entry points limit themselves, with or without a budget
        model = RobotModel(load_robot("one_segment"))
        orig = fwd._stage2

        def spy(*a, **k):
            seen.append(blas_threads())
            return orig(*a, **k)

        fwd._stage2 = spy
        try:
            solve_forward(model, np.full(model.A, 20e3))
        finally:
            fwd._stage2 = orig
        assert blas_threads() == outside
    assert seen == [{1}, {1}, {1}, {1}]
