"""``kdsl.bfloat16``: Warp's storage type (issue 14). Arrays hold 16-bit patterns; kernels
load float32 and store rounded to nearest even, bit for bit as the host converts."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslTypeError
from kdsl.ir import bfloat16 as bf
from kdsl.ir import parse_module, print_module

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")

# Ties (both directions), the largest finite values (one rounds to inf), denormals, NaNs.
SPECIAL = np.array(
    [0.0, -0.0, 1.0, 1.00390625, 1.01171875, 3.14159, -2.5e-3, 3.3895314e38, 3.4e38,
     1e-40, -1e-45, np.inf, -np.inf, np.nan, 65504.0, 1.0 + 2**-8 + 2**-20],
    dtype=np.float32,
)  # fmt: skip


def _values():
    rng = np.random.default_rng(5)
    bits = rng.integers(0, 2**32, 2000, dtype=np.uint64).astype(np.uint32).view(np.float32)
    return np.concatenate([SPECIAL, bits, rng.normal(size=500).astype(np.float32)])


def test_host_conversion_matches_ml_dtypes():
    ml_dtypes = pytest.importorskip("ml_dtypes")
    x = _values()
    with np.errstate(invalid="ignore"):
        want = x.astype(ml_dtypes.bfloat16).view(np.uint16)
    got = bf.to_bits(x)
    nan = np.isnan(x)
    np.testing.assert_array_equal(got[~nan], want[~nan])
    assert np.isnan(bf.from_bits(got[nan])).all()
    np.testing.assert_array_equal(
        bf.from_bits(want), want.view(ml_dtypes.bfloat16).astype(np.float32)
    )


def test_arrays_and_python_values():
    a = wp.array([1.0, 2.5, 3.14159], dtype=wp.bfloat16)
    assert a.dtype is wp.bfloat16 and a.shape == (3,)
    assert a.list() == [1.0, 2.5, 3.140625] and a[2] == np.float32(3.140625)
    assert wp.bfloat16(3.14159) == np.float32(3.140625)
    # uint16 data is taken as bits (as in Warp); ml_dtypes data as its values
    assert wp.array(np.array([0x3F80, 0x4040], np.uint16), dtype=wp.bfloat16).list() == [1, 3]
    assert wp.full(2, 1.25, dtype=wp.bfloat16).list() == [1.25, 1.25]
    assert wp.ones_like(a).list() == [1.0] * 3 and wp.clone(a).list() == a.list()
    c = wp.empty(2, dtype=wp.bfloat16)
    for src in ([3.0, 4.0], np.array([3.0, 4.0]), wp.array([3.0, 4.0], dtype=wp.bfloat16)):
        c.zero_()
        assert c.assign(src).list() == [3.0, 4.0]
    c[1] = 0.5
    assert c.list() == [3.0, 0.5]
    z = wp.zeros((2, 2), dtype=wp.bfloat16)
    z.fill_(0.1)
    bits = np.asarray(z.numpy()).view(np.uint16)
    assert (bits == bf.to_bits(np.float32(0.1))).all()
    ml_dtypes = pytest.importorskip("ml_dtypes")
    assert z.numpy().dtype == ml_dtypes.bfloat16  # else the uint16 bits
    assert wp.array(np.array([1.5], ml_dtypes.bfloat16), dtype=wp.bfloat16).list() == [1.5]


@wp.kernel
def _round_trip(x: wp.array(dtype=float), b: wp.array(dtype=wp.bfloat16), back: wp.array(dtype=float),
                r: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    b[i] = x[i]  # rounds
    back[i] = b[i] * 1.0  # loads as float32
    r[i] = wp.bfloat16(x[i] * 2.0)


@wp.kernel
def _views(m: wp.array2d(dtype=wp.bfloat16), out: wp.array(dtype=float)):
    i = wp.tid()
    row = m[i]
    out[i] = row[0] + row[1] + 0.5


def _run(backend, device):
    x = _values()
    n = x.size
    b = wp.zeros(n, dtype=wp.bfloat16, device=device)
    back, r = wp.zeros(n, device=device), wp.zeros(n, device=device)
    wp.launch(_round_trip, n, [wp.array(x, device=device), b, back, r], device=device,
              backend=backend)  # fmt: skip
    got = np.asarray(b.numpy()).view(np.uint16)
    nan = np.isnan(x)
    np.testing.assert_array_equal(got[~nan], bf.to_bits(x)[~nan])
    assert np.isnan(back.numpy()[nan]).all()
    np.testing.assert_array_equal(back.numpy()[~nan], bf.from_bits(bf.to_bits(x))[~nan])
    with np.errstate(over="ignore", invalid="ignore"):
        want_r = bf.from_bits(bf.to_bits(x * np.float32(2)))
    np.testing.assert_array_equal(r.numpy()[~nan], want_r[~nan])
    m = wp.array([[1.0, 2.0], [0.25, -4.0]], dtype=wp.bfloat16, device=device)
    out = wp.zeros(2, device=device)
    wp.launch(_views, 2, [m, out], device=device, backend=backend)
    assert out.numpy().tolist() == [3.5, -3.25]


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernels_load_float32_and_store_rounded(backend):
    _run(backend, "cpu")


@cuda
def test_kernels_load_float32_and_store_rounded_cuda():
    _run("cuda", "cuda:0")


def test_ir_text_form_round_trips():
    text = print_module(_views.build_module())
    assert "array<bf16, 2>" in text
    assert print_module(parse_module(text)) == text


def _compile(fn):
    wp.kernel(fn).build_module()


def test_misuse_is_a_clear_error():
    def atomic(a: wp.array(dtype=wp.bfloat16)):
        wp.atomic_add(a, 0, 1.0)

    def augmented(a: wp.array(dtype=wp.bfloat16)):
        a[0] += 1.0

    for fn in (atomic, augmented):
        with pytest.raises(KdslTypeError, match="atomic operations on bfloat16 arrays") as e:
            _compile(fn)
        assert "test_bfloat16.py" in str(e.value)

    def param(a: wp.array(dtype=float), s: wp.bfloat16):
        a[0] = 1.0

    with pytest.raises(KdslTypeError, match="parameter 's': bfloat16 is a storage type"):
        _compile(param)

    def f64_store(a: wp.array(dtype=wp.bfloat16), d: wp.float64):
        a[0] = d

    with pytest.raises(KdslTypeError, match="takes a float32 value, not a f64"):
        _compile(f64_store)

    with pytest.raises(TypeError, match="no vectors or matrices of it"):
        wp.vector(3, wp.bfloat16)
    with pytest.raises(KdslError, match="carry no gradients"):
        wp.zeros(2, dtype=wp.bfloat16, requires_grad=True)
    with pytest.raises(KdslTypeError, match="is a bfloat16, a storage type"):

        @wp.struct
        class _S:
            x: wp.bfloat16
