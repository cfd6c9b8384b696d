"""float32 ``sin``/``cos`` accuracy on every backend, against NumPy float64.

Dense: float32 values evenly spaced by bit pattern over ``|x| < 1e4`` (so every
binade from the denormals up is sampled), both signs. Special values: signed zeros,
denormals, the cpu fast path's bound (2^20), large arguments, infinities and NaN,
interleaved with ordinary values in one launch (a vectorized loop must pick each
lane's path). The cpu backend computes in float64 and rounds once
(``kdsl/backends/cpu/trig.py``): within 0.51 ulp; interp is NumPy's float32 (about
1.5 ulp) and CUDA documents 2 ulp for ``sinf``/``cosf``.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.testing.conformance import targets, ulp_distance

#: Max error in ulp per backend over the dense sample (|x| < 1e4).
MAX_ULP = {"cpu": 0.51, "interp": 2.0, "cuda": 2.0}
#: Dense sample size per sign (interp runs each thread in Python).
POINTS = {"cpu": 1 << 20, "interp": 1 << 12, "cuda": 1 << 20}
#: Beyond the cpu fast path (libm): 1 ulp.
LARGE_ULP = 1.0

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@wp.kernel
def sincos(x: wp.array(dtype=float), s: wp.array(dtype=float), c: wp.array(dtype=float)):
    i = wp.tid()
    s[i] = wp.sin(x[i])
    c[i] = wp.cos(x[i])


def _run(backend: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    (target,) = targets([backend])[:1]
    xa = wp.array(x, dtype=float, device=target.device)
    s = wp.zeros(len(x), dtype=float, device=target.device)
    c = wp.zeros(len(x), dtype=float, device=target.device)
    wp.launch(sincos, len(x), [xa, s, c], device=target.device, backend=backend)
    return s.numpy(), c.numpy()


def dense(count: int, bound: float = 1e4) -> np.ndarray:
    """``count`` float32 values evenly spaced by bit pattern in ``[0, bound)``, and negated."""
    top = int(np.float32(bound).view(np.uint32))
    x = np.linspace(0, top - 1, count).astype(np.uint32).view(np.float32)
    return np.concatenate([x, -x])


@pytest.mark.parametrize("backend", BACKENDS)
def test_dense_within_max_ulp(backend):
    x = dense(POINTS[backend])
    s, c = _run(backend, x)
    d = x.astype(np.float64)
    for name, got, want in (("sin", s, np.sin(d)), ("cos", c, np.cos(d))):
        err = ulp_distance(got, want)
        k = int(np.argmax(err))
        assert err[k] <= MAX_ULP[backend], (
            f"{backend} {name}({x[k]!r}) = {got[k]!r}, float64 {want[k]!r}: {err[k]:.3f} ulp"
        )


SMALL = np.array([0.0, -0.0, 1e-45, -1e-45, 1e-40, -1.1754942e-38, 1.17549435e-38, 3e-20],
                 dtype=np.float32)  # fmt: skip
LARGE = np.array([1048575.9, -1048576.0, 1048577.0, 3.0e6, -1e7, 16777216.0, 1e10, -1e20,
                  3.4028235e38, -3.4028235e38], dtype=np.float32)  # fmt: skip


@pytest.mark.parametrize("backend", BACKENDS)
def test_special_values(backend):
    # Interleaved with ordinary values, so neighbouring lanes take the other path.
    specials = np.concatenate([SMALL, LARGE, np.array([np.inf, -np.inf, np.nan], np.float32)])
    ordinary = np.linspace(-7.0, 7.0, len(specials)).astype(np.float32)
    x = np.stack([specials, ordinary], axis=1).ravel()
    s, c = _run(backend, x)
    s, c = s.reshape(-1, 2), c.reshape(-1, 2)
    d = ordinary.astype(np.float64)
    assert ulp_distance(s[:, 1], np.sin(d)).max() <= MAX_ULP[backend]
    assert ulp_distance(c[:, 1], np.cos(d)).max() <= MAX_ULP[backend]
    n = len(SMALL)
    # sin of a tiny value is the value itself, its sign included (sin(-0) = -0).
    np.testing.assert_array_equal(s[:n, 0], SMALL)
    assert np.array_equal(np.signbit(s[:n, 0]), np.signbit(SMALL))
    np.testing.assert_array_equal(c[:n, 0], np.ones(n, np.float32))
    big = LARGE.astype(np.float64)
    tol = max(MAX_ULP[backend], LARGE_ULP)
    assert ulp_distance(s[n : n + len(LARGE), 0], np.sin(big)).max() <= tol
    assert ulp_distance(c[n : n + len(LARGE), 0], np.cos(big)).max() <= tol
    assert np.isnan(s[-3:, 0]).all() and np.isnan(c[-3:, 0]).all()  # sin(+-inf), sin(NaN)
