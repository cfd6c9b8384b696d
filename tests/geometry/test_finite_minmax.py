"""``kdsl.geometry.finite_minmax``: the componentwise min and max of finite vec3 (box
bounds over checked points) agree with NumPy's on the interpreter and the cpu backend,
and compile to plain compares (no ``minimumnum``) on the cpu."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.geometry.finite_minmax import high3, low3

V3 = wp.vec3
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


@wp.kernel
def bounds_kernel(a: wp.array(dtype=V3), b: wp.array(dtype=V3), lo: wp.array(dtype=V3),
                  hi: wp.array(dtype=V3)):  # fmt: skip
    i = wp.tid()
    lo[i] = low3(a[i], b[i])
    hi[i] = high3(a[i], b[i])


@pytest.mark.parametrize("backend", ["interp", "cpu", pytest.param("cuda", marks=cuda)])
def test_low3_high3_are_the_componentwise_min_and_max(backend):
    device = "cuda:0" if backend == "cuda" else "cpu"
    rng = np.random.default_rng(4)
    a = rng.normal(size=(257, 3)).astype(np.float32)
    b = rng.normal(size=(257, 3)).astype(np.float32)
    b[:20] = a[:20]  # ties
    b[20:40, 1] = a[20:40, 1]
    lo, hi = wp.zeros(257, dtype=V3, device=device), wp.zeros(257, dtype=V3, device=device)
    wp.launch(bounds_kernel, dim=257, backend=backend, device=device,
              inputs=[wp.array(a, dtype=V3, device=device), wp.array(b, dtype=V3, device=device),
                      lo, hi])  # fmt: skip
    np.testing.assert_array_equal(lo.numpy(), np.minimum(a, b))
    np.testing.assert_array_equal(hi.numpy(), np.maximum(a, b))


def test_low3_high3_lower_to_compares_on_the_cpu():
    from kdsl.backends.cpu import BACKEND
    from kdsl.compiler import lower

    text = lower(BACKEND, bounds_kernel.build_module(), "llvm-ir", None)
    assert "minimumnum" not in text and "maximumnum" not in text
    assert "fcmp" in text
