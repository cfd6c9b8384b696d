"""``kdsl.geometry.host_read.IntsReader``: the values as of ``start``, read back without
waiting for the work issued after it (which leaves the source alone until the values are
read); refused while a capture is open."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.geometry.host_read import IntsReader

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


@wp.kernel
def _bump(a: wp.array(dtype=wp.int32), by: wp.int32):
    i = wp.tid()
    a[i] = a[i] + by


@pytest.mark.parametrize("device", DEVICES)
def test_values_as_of_start(device):
    a = wp.array(np.array([3, -4], np.int32), device=device)
    other = wp.zeros(1 << 20, dtype=wp.int32, device=device)
    read = IntsReader(a)
    for k in range(3):  # the same reader again: its buffer and events are reused
        wp.launch(_bump, dim=2, inputs=[a, 10], device=device)
        read.start()
        wp.launch(_bump, dim=other.shape[0], inputs=[other, 1], device=device)  # after it
        assert read.values() == (13 + 10 * k, 6 + 10 * k)
    assert a.numpy().tolist() == [33, 26]
    assert other.numpy()[-1] == 3


@pytest.mark.parametrize("device", DEVICES)
def test_refused_in_a_capture(device):
    a = wp.zeros(2, dtype=wp.int32, device=device)
    read = IntsReader(a)
    wp.capture_begin(device=device)
    try:
        with pytest.raises(KdslError, match="capture"):
            read.start()
    finally:
        wp.capture_end(device=device)
