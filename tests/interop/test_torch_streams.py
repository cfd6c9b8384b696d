"""Ordering kdsl's stream with PyTorch's: which cases need an event, and who waits for whom.

The decisions (``kdsl.interop.torch_streams``) are tested here with stand-in streams,
so they run without a GPU; the tests at the end run them for real on one (skipped
without a GPU): the fast ``to_torch`` and direct-launch paths give the right data on
the default stream and on a PyTorch side stream.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError
from kdsl.interop import torch_streams as ts
from kdsl.interop.torch import VIEWS
from tests.interop.kernels import double_vec, saxpy


class _CpStream:
    """Stands in for ``cupy.cuda.Stream`` (a stream kdsl created)."""

    def __init__(self, non_blocking: bool = False) -> None:
        self.is_non_blocking = non_blocking


class _CpExternal:
    """Stands in for ``cupy.cuda.ExternalStream`` (a wrapped handle)."""

    is_non_blocking = False  # what CuPy reports for a wrapped handle, whatever it is


class _Stream:
    """What ``torch_streams`` reads of a kdsl ``Stream``, and a log of its waits."""

    def __init__(self, handle: int, cp: object, log: list | None = None) -> None:
        self.cuda_stream, self.cupy, self.log = handle, cp, log

    @property
    def is_blocking(self) -> bool:
        return not self.cupy.is_non_blocking

    def wait_stream(self, other: "_Stream") -> None:
        self.log.append((self.cuda_stream, "waits for", other.cuda_stream))


@pytest.fixture
def fake_cupy(monkeypatch):
    class _Cuda:
        Stream = _CpStream

    class _Cupy:
        cuda = _Cuda

    monkeypatch.setattr(ts, "cupy", lambda: _Cupy)


def test_same_stream_or_legacy_with_an_own_blocking_stream_needs_no_event(fake_cupy):
    own = _Stream(0x5000, _CpStream())
    assert ts.implicitly_ordered(own, 0x5000)  # one stream: program order
    assert ts.implicitly_ordered(own, ts.LEGACY)  # CUDA orders legacy and blocking streams
    assert not ts.implicitly_ordered(own, 0x7000)  # a PyTorch side stream
    assert not ts.implicitly_ordered(_Stream(0x5000, _CpStream(non_blocking=True)), ts.LEGACY)
    # A wrapped handle may be a non-blocking stream (PyTorch creates its streams so).
    assert not ts.implicitly_ordered(_Stream(0x5000, _CpExternal()), ts.LEGACY)
    assert ts.implicitly_ordered(_Stream(0x5000, _CpExternal()), 0x5000)


@pytest.mark.parametrize("torch_raw, waits", [(ts.LEGACY, False), (0x5000, False), (0x7000, True)])
def test_each_direction_waits_only_when_needed(fake_cupy, monkeypatch, torch_raw, waits):
    log: list = []
    kdsl_stream = _Stream(0x5000, _CpStream(), log)
    monkeypatch.setattr(ts, "current_stream", lambda device: kdsl_stream)
    monkeypatch.setattr(ts, "Stream", lambda device, cuda_stream: _Stream(cuda_stream, None, log))
    ts.kdsl_waits_for_torch("cuda:0", torch_raw)
    ts.torch_waits_for_kdsl("cuda:0", torch_raw)
    expected = [(0x5000, "waits for", torch_raw), (torch_raw, "waits for", 0x5000)]
    assert log == (expected if waits else [])


def test_raw_stream_reader_prefers_the_c_function_and_falls_back():
    class _C:
        @staticmethod
        def _cuda_getCurrentRawStream(ordinal):
            return 0x100 + ordinal

    class Fast:
        pass

    Fast._C = _C
    assert ts.raw_stream_reader(Fast())(2) == 0x102

    class _PublicStream:
        def __init__(self, ordinal):
            self.cuda_stream = 0x200 + ordinal

    class _Cuda:
        current_stream = _PublicStream

    class Slow:
        _C = object()
        cuda = _Cuda

    assert ts.raw_stream_reader(Slow())(3) == 0x203


# --- on a GPU --------------------------------------------------------------------------

DEV = "cuda:0"
try:
    import torch
except ImportError:  # the stand-in tests above still run
    torch = None
gpu = pytest.mark.skipif(
    torch is None or not (wp.is_cuda_available() and torch.cuda.is_available()),
    reason="needs a CUDA device seen by kdsl and PyTorch",
)


@gpu
def test_to_torch_cuda_fast_path_shares_memory_types_and_grads():
    a = wp.zeros(1 << 16, dtype=float, device=DEV)
    a.fill_(4.0)  # on kdsl's (blocking) stream; torch's default stream is ordered after it
    t = wp.to_torch(a)
    assert t.data_ptr() == a.ptr and t.device == torch.device(DEV)
    assert t.sum().item() == 4.0 * (1 << 16)
    u = wp.to_torch(wp.array(np.arange(3, dtype=np.uint32), device=DEV))
    assert u.dtype == torch.int32 and u.tolist() == [0, 1, 2]
    v = wp.zeros(2, dtype=wp.vec3, device=DEV, requires_grad=True)
    tv = wp.to_torch(v)
    assert tv.shape == (2, 3) and tv.requires_grad and tv.grad.data_ptr() == v.grad.ptr
    assert tv.grad.shape == (2, 3)
    empty = wp.to_torch(wp.zeros(0, dtype=float, device=DEV))  # DLPack path
    assert empty.shape == (0,) and empty.device == torch.device(DEV)
    m = wp.array(np.arange(12, dtype=np.float32).reshape(3, 4), device=DEV)
    tm = wp.to_torch(m)
    assert tm.shape == (3, 4) and tm.stride() == (4, 1) and tm[2, 1].item() == 9.0
    del a  # the tensor keeps the memory alive
    assert t[-1].item() == 4.0


@gpu
def test_to_torch_cuda_hands_out_fresh_aliases_of_one_tensor():
    a = wp.array(np.arange(4, dtype=np.float32), device=DEV)
    t1, t2 = wp.to_torch(a), wp.to_torch(a)
    assert t1 is not t2 and t1.data_ptr() == t2.data_ptr() == a.ptr
    t1.requires_grad_(True)  # one alias's autograd state is not the next call's
    assert not t2.requires_grad and not wp.to_torch(a).requires_grad
    t2.add_(1.0)  # aliases share a version counter: autograd sees the write
    assert t1._version == t2._version and a.numpy().tolist() == [1.0, 2.0, 3.0, 4.0]
    g = wp.zeros(4, dtype=float, device=DEV, requires_grad=True)
    tg1, tg2 = wp.to_torch(g), wp.to_torch(g)
    assert tg1.requires_grad and tg2.requires_grad and tg1.grad is not tg2.grad
    assert tg1.grad.data_ptr() == tg2.grad.data_ptr() == g.grad.ptr


@gpu
def test_to_torch_on_a_torch_side_stream_is_ordered():
    a = wp.zeros(1 << 20, dtype=float, device=DEV)
    s = torch.cuda.Stream()
    with torch.cuda.stream(s):
        a.fill_(3.0)
        t = wp.to_torch(a)  # torch's side stream needs an event: the DLPack path
        total = t.sum()
    s.synchronize()
    assert total.item() == 3.0 * (1 << 20)


@gpu
def test_direct_cuda_launches_use_the_view_cache_and_follow_the_tensor():
    x = torch.ones(8, device=DEV)
    y = torch.zeros(8, device=DEV, requires_grad=True)
    hits = VIEWS.hits
    for _ in range(3):
        wp.launch(saxpy, dim=8, inputs=[x, y, 1.0], device=DEV)
    wp.synchronize()
    assert VIEWS.hits >= hits + 4 and y.detach().tolist() == [3.0] * 8
    y.data = torch.zeros(8, device=DEV)  # new memory behind the same object
    wp.launch(saxpy, dim=8, inputs=[x, y, 2.0], device=DEV)
    wp.synchronize()
    assert y.detach().tolist() == [2.0] * 8
    v = torch.ones(4, 3, device=DEV)
    wp.launch(double_vec, dim=4, inputs=[v], device=DEV)
    wp.synchronize()
    assert (v == 2.0).all().item()
    with pytest.raises(KdslLaunchError, match="float64"):
        wp.launch(saxpy, dim=8, inputs=[x.double(), y, 1.0], device=DEV)


@gpu
def test_direct_cuda_launch_waits_for_a_torch_side_stream():
    n = 1 << 20
    x = torch.zeros(n, device=DEV)
    y = torch.zeros(n, device=DEV)
    torch.cuda.synchronize()
    s = torch.cuda.Stream()  # non-blocking: CUDA does not order it with kdsl's stream
    with torch.cuda.stream(s):
        torch.cuda._sleep(20_000_000)  # keeps the side stream busy for milliseconds
        x.fill_(2.0)
        wp.launch(saxpy, dim=n, inputs=[x, y, 1.0], device=DEV)  # must see the fill
    wp.synchronize()
    torch.cuda.synchronize()
    assert (y == 2.0).all().item()
