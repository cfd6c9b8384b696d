"""DLPack producers that report no device id (Paddle 3.3 says ``(kDLCPU, None)``):
host data works directly, in ``from_dlpack`` and in ``launch``; a GPU producer without
an id, or an unreadable device, is a clear kdsl error, never a raw TypeError (issue 13)."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError
from kdsl.interop.dtypes import InteropDeviceError, InteropTypeError

KDL_CPU, KDL_CUDA = 1, 2


class Producer:
    """A DLPack producer over a NumPy array that reports ``device`` as its device."""

    def __init__(self, data: np.ndarray, device: tuple) -> None:
        self.data = data
        self.device = device

    def __dlpack__(self, **kwargs):
        return self.data.__dlpack__(**kwargs)

    def __dlpack_device__(self):
        return self.device


@wp.kernel
def _increment(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] + 1.0


def test_host_producer_without_device_id_reads_through_from_dlpack():
    data = np.arange(4, dtype=np.float32)
    a = wp.from_dlpack(Producer(data, (KDL_CPU, None)))
    assert a.device.is_cpu and a.ptr == data.ctypes.data
    np.testing.assert_array_equal(a.numpy(), data)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_host_producer_without_device_id_passes_to_launch(backend):
    data = np.zeros(4, dtype=np.float32)
    wp.launch(_increment, 4, [Producer(data, (KDL_CPU, None))], backend=backend)
    np.testing.assert_array_equal(data, np.ones(4))


def test_gpu_producer_without_device_id_is_a_clear_error():
    gpu = Producer(np.zeros(4, np.float32), (KDL_CUDA, None))
    with pytest.raises(InteropDeviceError, match="without a device id"):
        wp.from_dlpack(gpu)
    with pytest.raises(KdslLaunchError, match="argument 0 'a'"):
        wp.launch(_increment, 4, [gpu], device="cpu")


def test_unreadable_device_is_a_clear_error():
    with pytest.raises(InteropTypeError, match="reports a DLPack device kdsl cannot read"):
        wp.from_dlpack(Producer(np.zeros(2, np.float32), ("cpu", 0)))
