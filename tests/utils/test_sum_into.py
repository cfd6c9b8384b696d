"""``kdsl.utils.reduce.SumInto``: a prepared ``array_sum(values, out=out)`` gives the same
bits as ``array_sum`` call after call, and refuses what it cannot sum."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.utils import UtilsError, array_sum
from kdsl.utils.reduce import SumInto

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [1, 7, 1000, 300_001])
@pytest.mark.parametrize("dtype", [wp.float32, wp.float64])
def test_same_bits_as_array_sum_after_every_change(device, n, dtype):
    rng = np.random.default_rng(n)
    values = wp.array(rng.random(n) * 100, dtype=dtype, device=device)
    out, want = wp.zeros(1, dtype=dtype, device=device), wp.zeros(1, dtype=dtype, device=device)
    total = SumInto(values, out)
    for scale in (1.0, -3.5, 1e-3):
        values.assign(wp.array(rng.random(n) * scale, dtype=dtype, device=device))
        total()
        array_sum(values, out=want)
        assert out.numpy().tobytes() == want.numpy().tobytes()


def test_views_of_one_block():
    """Values and out may be views of one array (a mesh keeps both in one block)."""
    block = wp.array(np.arange(11, dtype=np.float32), device="cpu")
    SumInto(block[:10], block[10:])()
    assert block.numpy()[10] == 45.0


@pytest.mark.parametrize(
    ("values", "out", "message"),
    [
        (lambda: wp.zeros(4, dtype=wp.int32), lambda: wp.zeros(1, dtype=wp.int32), "float"),
        (lambda: wp.zeros(4, dtype=wp.vec3), lambda: wp.zeros(1, dtype=wp.vec3), "float"),
        (lambda: wp.zeros((2, 2), dtype=wp.float32), lambda: wp.zeros(1), "1-d"),
        (lambda: wp.zeros(8, dtype=wp.float32)[::2], lambda: wp.zeros(1), "contiguous"),
        (lambda: wp.zeros(4, dtype=wp.float32), lambda: wp.zeros(2), "shape"),
        (lambda: wp.zeros(4, dtype=wp.float32), lambda: wp.zeros(1, dtype=wp.float64), "hold"),
        (lambda: np.zeros(4, np.float32), lambda: wp.zeros(1), "kdsl array"),
    ],
)
def test_bad_arguments(values, out, message):
    with pytest.raises(UtilsError, match=message):
        SumInto(values(), out())
