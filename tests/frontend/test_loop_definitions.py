"""A name first assigned inside a ``for`` loop is readable after it when the loop surely
runs and every iteration assigns it (Python's and Warp's rule); otherwise it stays a
located "may be unassigned" error."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslNameError

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@wp.struct
class Hit:
    t: float
    n: wp.vec3


@wp.kernel
def last_values(out: wp.array(dtype=float), vout: wp.array(dtype=wp.vec3)):
    t = wp.float32(0.0)
    for i in range(1, 5):
        d = t + 1.0  # scalar
        v = wp.vec3(float(i), d, 0.0)  # vector
        h = Hit(d, v)  # struct
        t = t + d
    out[0] = d
    out[1] = t
    out[2] = h.t
    vout[0] = v


@pytest.mark.parametrize("backend", BACKENDS)
def test_values_of_the_last_iteration(backend):
    device = "cuda:0" if backend == "cuda" else "cpu"
    out = wp.zeros(3, dtype=float, device=device)
    vout = wp.zeros(1, dtype=wp.vec3, device=device)
    wp.launch(last_values, dim=1, inputs=[out, vout], device=device, backend=backend)
    # t: 0 -> 1 -> 3 -> 7 -> 15; the last d is 8.
    np.testing.assert_array_equal(out.numpy(), [8.0, 15.0, 8.0])
    np.testing.assert_array_equal(vout.numpy()[0], [4.0, 8.0, 0.0])


def _refused(kernel, name):
    with pytest.raises(KdslNameError, match=f"variable '{name}' may be unassigned") as err:
        kernel.build_module()
    assert "test_loop_definitions.py" in str(err.value)


def test_a_loop_that_may_not_run_still_refuses():
    @wp.kernel
    def zero_trip(n: int, out: wp.array(dtype=float)):
        for _ in range(n):  # n may be 0
            d = 1.0
        out[0] = d

    @wp.kernel
    def empty_range(out: wp.array(dtype=float)):
        for _ in range(3, 3):
            d = 1.0
        out[0] = d

    _refused(zero_trip, "d")
    _refused(empty_range, "d")


def test_a_conditional_assignment_or_an_early_exit_still_refuses():
    @wp.kernel
    def sometimes(out: wp.array(dtype=float)):
        for i in range(4):
            if i > 2:
                d = 1.0
        out[0] = d

    @wp.kernel
    def breaks_first(out: wp.array(dtype=float)):
        for _ in range(4):
            if out[0] > 0.0:
                break
            d = 1.0
        out[0] = d

    _refused(sometimes, "d")
    _refused(breaks_first, "d")
