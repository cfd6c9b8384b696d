"""Devices, streams, events and synchronization.

The CPU-side rules run everywhere; the CUDA tests are skipped without a GPU.
"""

import subprocess
import sys

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
two_gpus = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")


@pytest.fixture(autouse=True)
def _restore_default_device():
    saved = wp.get_device()
    yield
    wp.set_device(saved)


# --- CPU rules (run everywhere) ----------------------------------------------------------------


def test_import_does_not_load_cupy():
    code = "import kdsl, sys; kdsl.zeros(3); assert 'cupy' not in sys.modules, 'cupy imported'"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize("name", ["gpu", "cuda:x", "cuda:", "CPU", "cuda:-1", "cuda0"])
def test_unknown_device_names_list_the_spellings(name):
    with pytest.raises(KdslError, match=r"unknown device .*'cpu', 'cuda'.*'cuda:N'"):
        wp.get_device(name)


def test_non_string_device_is_an_error():
    with pytest.raises(KdslError, match="named by a string"):
        wp.get_device(3)


def test_missing_cuda_device_names_how_many_there_are():
    n = wp.get_cuda_device_count()
    with pytest.raises(KdslError, match=rf"'cuda:{n + 7}' is not available"):
        wp.get_device(f"cuda:{n + 7}")
    with pytest.raises(KdslError, match="not available"):
        wp.zeros(3, device=f"cuda:{n}")


@pytest.mark.skipif(wp.is_cuda_available(), reason="only without CUDA")
def test_without_cuda():
    assert wp.get_cuda_devices() == []
    assert wp.get_preferred_device() == "cpu"
    with pytest.raises(KdslError, match="no CUDA devices"):
        wp.get_device("cuda")


def test_cpu_device_properties():
    d = wp.get_device("cpu")
    assert d.is_cpu and not d.is_cuda and d.ordinal == -1 and d.alias == "cpu"
    assert d.name == "CPU" and d.arch == 0
    assert d.total_memory >= d.free_memory >= 0
    assert d.can_access("cpu") and d == "cpu" and d != "gpu"
    d.make_current()  # a no-op


def test_scoped_device_cpu_sets_and_restores_the_default():
    wp.set_device("cpu")
    with wp.ScopedDevice("cpu") as d:
        assert d == "cpu" and wp.get_device() == "cpu"
        assert wp.zeros(2).device == "cpu"
    assert wp.get_device() == "cpu"


@pytest.mark.parametrize(
    "call",
    [
        lambda: wp.Stream("cpu"),
        lambda: wp.Event("cpu"),
        lambda: wp.get_stream("cpu"),
        lambda: wp.synchronize_stream("cpu"),
        lambda: wp.get_device("cpu").stream,
    ],
)
def test_streams_and_events_need_a_cuda_device(call):
    with pytest.raises(KdslError, match="needs a CUDA device, but 'cpu' is not one"):
        call()


def test_module_level_stream_functions_on_a_cpu_default_are_errors():
    wp.set_device("cpu")
    for call in (wp.record_event, lambda: wp.wait_event(None), lambda: wp.wait_stream(None)):
        with pytest.raises(KdslError, match="needs a CUDA device"):
            call()


def test_cpu_synchronization_is_a_no_op():
    wp.synchronize()
    wp.synchronize_device("cpu")
    wp.synchronize_device()


def test_scoped_stream_none_does_nothing():
    with wp.ScopedStream(None) as s:
        assert s is None
    assert wp.get_device() == "cpu"


def test_set_stream_rejects_non_streams():
    with pytest.raises(KdslError, match=r"takes a kdsl\.Stream"):
        wp.set_stream("cuda")


def test_cpu_array_has_no_cuda_interface():
    a = wp.zeros(3)
    assert not hasattr(a, "__cuda_array_interface__")
    assert hasattr(a, "__array_interface__")


def test_copy_rejects_a_non_stream():
    a, b = wp.zeros(3), wp.ones(3)
    with pytest.raises(KdslError, match=r"stream must be a kdsl\.Stream"):
        wp.copy(a, b, stream="cuda")
    wp.copy(a, b)
    np.testing.assert_array_equal(a.numpy(), 1)


# --- CUDA -----------------------------------------------------------------------------------


@cuda
def test_cuda_devices_and_properties():
    devs = wp.get_cuda_devices()
    assert len(devs) == wp.get_cuda_device_count() >= 1
    d = wp.get_device("cuda:0")
    assert d is devs[0] and d.is_cuda and d.ordinal == 0 and d.alias == "cuda:0"
    assert isinstance(d.name, str) and d.name
    assert d.arch >= 50
    assert d.total_memory > d.free_memory > 0
    assert wp.get_device("cuda") == "cuda:0"
    assert wp.get_preferred_device() == "cuda:0"
    assert d.can_access(d) and not d.can_access("cpu")


@cuda
def test_scoped_device_makes_cuda_current():
    import cupy

    wp.set_device("cpu")
    with wp.ScopedDevice("cuda:0"):
        assert wp.get_device() == "cuda:0"
        assert cupy.cuda.runtime.getDevice() == 0
        assert wp.zeros(4).device == "cuda:0"
    assert wp.get_device() == "cpu"


@cuda
@two_gpus
def test_cuda_alias_follows_the_current_device():
    import cupy

    with wp.ScopedDevice("cuda:1"):
        assert wp.get_device("cuda") == "cuda:1"
        assert cupy.cuda.runtime.getDevice() == 1
        assert wp.zeros(2, device="cuda").device == "cuda:1"
    assert wp.get_device("cuda") == "cuda:0"


@cuda
def test_stream_objects():
    s = wp.Stream("cuda:0")
    assert s.device == "cuda:0"
    assert isinstance(s.cuda_stream, int) and s.cuda_stream != 0
    assert s.cupy.ptr == s.cuda_stream
    assert s.is_blocking and s.__cuda_stream__() == (0, s.cuda_stream)
    assert not wp.Stream("cuda:0", blocking=False).is_blocking
    assert s != wp.Stream("cuda:0")
    ext = wp.Stream("cuda:0", cuda_stream=s.cuda_stream)
    assert ext == s and ext.cuda_stream == s.cuda_stream
    s.synchronize()
    assert s.is_complete


@cuda
def test_get_stream_is_stable_and_never_the_legacy_stream():
    s = wp.get_stream("cuda:0")
    assert s is wp.get_stream("cuda:0") is wp.get_device("cuda:0").stream
    assert s.cuda_stream not in (0, 1, 2)
    with wp.ScopedDevice("cuda:0"):
        assert wp.get_stream() is s


@cuda
def test_set_stream_and_scoped_stream():
    base = wp.get_stream("cuda:0")
    s = wp.Stream("cuda:0")
    wp.set_device("cpu")
    with wp.ScopedStream(s, sync_exit=True) as got:
        assert got is s
        assert wp.get_stream("cuda:0") is s
        assert wp.get_device() == "cuda:0"  # the scope also selects the stream's device
        a = wp.full(1 << 20, 2.0, device="cuda:0")  # enqueued on s
    assert wp.get_stream("cuda:0") is base and wp.get_device() == "cpu"
    assert np.all(a.numpy() == 2.0)
    wp.set_stream(s, sync=True)
    assert wp.get_stream("cuda:0") is s
    wp.set_stream(base)
    with pytest.raises(KdslError, match="the stream is on 'cuda:0', not on 'cpu'"):
        wp.set_stream(s, device="cpu")


@cuda
def test_work_on_a_user_stream_is_ordered_by_events():
    a = wp.zeros(1 << 22, dtype=float, device="cuda:0")
    producer = wp.Stream("cuda:0")
    with wp.ScopedStream(producer, sync_enter=True):
        a.fill_(3.0)
        done = wp.record_event()
    consumer = wp.get_stream("cuda:0")
    consumer.wait_event(done)
    b = wp.clone(a)  # on the device's current stream, after the event
    np.testing.assert_array_equal(b.numpy()[:: 1 << 16], 3.0)
    wp.synchronize_event(done)
    assert done.is_complete


@cuda
def test_wait_stream_orders_two_streams():
    s1, s2 = wp.Stream("cuda:0"), wp.Stream("cuda:0")
    a = wp.zeros(1 << 22, device="cuda:0")
    with wp.ScopedStream(s1):
        a.fill_(7.0)
    s2.wait_stream(s1)
    out = wp.empty(a.shape, device="cpu")
    wp.copy(out, a, stream=s2)
    wp.synchronize_stream(s2)
    assert out.numpy()[0] == 7.0 and out.numpy()[-1] == 7.0


@cuda
def test_module_level_event_functions_use_the_default_device():
    with wp.ScopedDevice("cuda:0"):
        other = wp.Stream()
        e = wp.record_event()
        assert e.device == "cuda:0"
        wp.wait_event(e)
        wp.wait_stream(other)
        e2 = wp.Event()
        assert wp.record_event(e2) is e2
        wp.synchronize_stream()
        wp.synchronize_device()
        wp.synchronize()


@cuda
def test_event_timing():
    start = wp.Event("cuda:0", enable_timing=True)
    end = wp.Event("cuda:0", enable_timing=True)
    s = wp.get_stream("cuda:0")
    s.record_event(start)
    wp.zeros(1 << 24, device="cuda:0").fill_(1.0)
    end.record()
    ms = wp.get_event_elapsed_time(start, end)
    assert isinstance(ms, float) and ms >= 0.0
    plain = s.record_event()
    with pytest.raises(KdslError, match="enable_timing=True"):
        wp.get_event_elapsed_time(start, plain)


@cuda
@two_gpus
def test_event_of_another_device_cannot_be_recorded_here():
    e = wp.Event("cuda:1")
    with pytest.raises(KdslError, match="cannot be recorded"):
        wp.get_stream("cuda:0").record_event(e)
    wp.get_stream("cuda:0").wait_event(wp.get_stream("cuda:1").record_event(e))  # waiting is fine
    wp.synchronize()
