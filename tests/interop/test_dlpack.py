"""DLPack on the CPU: __dlpack__/__dlpack_device__, from_dlpack, to_dlpack, both capsule kinds."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.interop.dlpack import capsule_device


class Producer:
    """A minimal DLPack producer that is not NumPy (what other libraries look like)."""

    def __init__(self, data):
        self.data = data
        self.calls = []

    def __dlpack_device__(self):
        return self.data.__dlpack_device__()

    def __dlpack__(self, **kwargs):
        self.calls.append(kwargs)
        return self.data.__dlpack__(**kwargs)


@wp.kernel
def add_one(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0


def test_dlpack_device_of_a_cpu_array():
    assert wp.zeros(2).__dlpack_device__() == (1, 0)


def test_dunder_dlpack_gives_versioned_or_legacy_capsules():
    a = wp.zeros(3, dtype=wp.vec3)
    assert "dltensor_versioned" in repr(a.__dlpack__(max_version=(1, 0)))
    assert '"dltensor"' in repr(a.__dlpack__())
    assert capsule_device(a.__dlpack__()) == (1, 0)
    assert capsule_device(a.__dlpack__(max_version=(1, 0))) == (1, 0)


def test_numpy_reads_a_kdsl_array_through_dlpack_zero_copy():
    a = wp.zeros(4, dtype=wp.vec3)
    n = np.from_dlpack(a)
    assert n.shape == (4, 3) and n.ctypes.data == a.ptr  # element dims appended
    n[2, 1] = 9.0
    assert a.numpy()[2, 1] == 9.0


@pytest.mark.parametrize("max_version", [None, (1, 0)])
def test_from_dlpack_reads_capsules_of_both_kinds_zero_copy(max_version):
    src = np.arange(6, dtype=np.float32)
    kw = {} if max_version is None else {"max_version": max_version}
    a = wp.from_dlpack(src.__dlpack__(**kw))
    assert a.ptr == src.ctypes.data and a.dtype is wp.float32
    a.fill_(2.0)
    assert (src == 2.0).all()


def test_from_dlpack_producer_object_and_vector_dtype():
    src = np.arange(12, dtype=np.float32).reshape(4, 3)
    p = Producer(src)
    a = wp.from_dlpack(p, dtype=wp.vec3)
    assert a.shape == (4,) and a.dtype is wp.vec3 and a.ptr == src.ctypes.data
    assert p.calls and p.calls[0].get("stream") is None  # a CPU producer gets no stream
    assert a[1].tolist() == [3.0, 4.0, 5.0]


def test_from_dlpack_matrix_dtype_and_reinterpreted_signedness():
    m = wp.from_dlpack(np.zeros((5, 2, 2), np.float32), dtype=wp.mat22)
    assert m.shape == (5,) and m.dtype is wp.mat22
    u = wp.from_dlpack(np.full(3, -1, np.int32), dtype=wp.uint32)
    assert u.numpy().tolist() == [2**32 - 1] * 3


def test_used_capsule_is_refused():
    cap = np.zeros(2, np.float32).__dlpack__()
    wp.from_dlpack(cap)
    with pytest.raises(KdslError, match="already consumed"):
        wp.from_dlpack(cap)


def test_from_dlpack_errors():
    with pytest.raises(KdslError, match="__dlpack__ or a DLPack capsule"):
        wp.from_dlpack([1.0, 2.0])
    with pytest.raises(TypeError, match=r"complex64 .*no kdsl equivalent"):
        wp.from_dlpack(np.zeros(2, np.complex64))
    with pytest.raises(KdslError, match="components are float32"):
        wp.from_dlpack(np.zeros((2, 3), np.float64), dtype=wp.vec3)
    with pytest.raises(KdslError, match="last dim must be 3"):
        wp.from_dlpack(np.zeros((2, 4), np.float32), dtype=wp.vec3)
    with pytest.raises(KdslError, match="must be contiguous"):
        wp.from_dlpack(np.zeros((3, 6), np.float32)[:, ::2], dtype=wp.vec3)


def test_to_dlpack_round_trips_through_numpy_and_kdsl():
    a = wp.array(np.arange(6, dtype=np.float32), dtype=wp.float32)
    b = wp.from_dlpack(wp.to_dlpack(a))
    assert b.ptr == a.ptr
    c = wp.from_dlpack(wp.to_dlpack(a, max_version=(1, 0)))
    assert c.ptr == a.ptr
    with pytest.raises(KdslError, match="takes a kdsl array"):
        wp.to_dlpack(np.zeros(2))


def test_dlpack_producers_launch_directly():
    src = np.zeros(4, np.float32)
    wp.launch(add_one, dim=4, inputs=[Producer(src)])
    assert (src == 1.0).all()
    with pytest.raises(KdslLaunchError, match="float64 array; convert it"):
        wp.launch(add_one, dim=4, inputs=[Producer(np.zeros(4))])


def test_array_interface_objects_launch_directly():
    class Host:
        def __init__(self, data):
            self.__array_interface__ = data.__array_interface__
            self.keep = data

    src = np.zeros(4, np.float32)
    wp.launch(add_one, dim=4, inputs=[Host(src)])
    assert (src == 1.0).all()


def test_descriptor_from_a_non_torch_source_launches():
    # ArrayDescriptor is what return_ctype=True gives; build one directly here.
    from kdsl.ir import types as T
    from kdsl.runtime.descriptor import ArrayDescriptor

    src = np.zeros(4, np.float32)
    d = ArrayDescriptor(src, T.F32, wp.get_device("cpu"))
    wp.launch(add_one, dim=4, inputs=[d])
    assert (src == 1.0).all() and d.shape == (4,)
    bad = ArrayDescriptor(np.zeros(4, np.int32), T.I32, wp.get_device("cpu"))
    with pytest.raises(KdslLaunchError, match="expected an array of f32, got an array of i32"):
        wp.launch(add_one, dim=4, inputs=[bad])
