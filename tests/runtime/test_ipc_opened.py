"""CUDA IPC's opened objects without a GPU, over a stand-in for CuPy's runtime: a refused
handle is a KdslError naming the call and the device, and a mapped allocation or an
opened event is released with its own CUDA call, on its own device, once collected
(tests/runtime/test_multi_gpu.py covers the real thing on a GPU)."""

from __future__ import annotations

import gc
import types
from contextlib import contextmanager

import pytest

from kdsl.errors import KdslError
from kdsl.runtime import ipc


class _Runtime:
    """CuPy's ``cuda.runtime`` as far as kdsl.runtime.ipc uses it, recording calls."""

    class CUDARuntimeError(RuntimeError):
        pass

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.device = None

    def ipcOpenMemHandle(self, handle):
        raise self.CUDARuntimeError("cudaErrorInvalidValue")

    def ipcOpenEventHandle(self, handle):
        self.calls.append(("open event", self.device))
        return 4242

    def ipcCloseMemHandle(self, ptr):
        self.calls.append(("close", ptr, self.device))

    def eventDestroy(self, ptr):
        self.calls.append(("destroy", ptr, self.device))


@pytest.fixture
def runtime(monkeypatch):
    rt = _Runtime()

    @contextmanager
    def device(ordinal):
        rt.device, before = ordinal, rt.device
        yield
        rt.device = before

    fake = types.SimpleNamespace(cuda=types.SimpleNamespace(runtime=rt, Device=device))
    monkeypatch.setattr(ipc, "cupy", lambda: fake)
    return rt


def test_a_refused_handle_names_the_call_and_the_device(runtime):
    dev = type("Dev", (), {"ordinal": 1, "__str__": lambda self: "cuda:1"})()
    with pytest.raises(KdslError, match=r"from_ipc_handle\(\): CUDA could not open the handle "
                       r"on 'cuda:1' \(a hint\): cudaErrorInvalidValue"):  # fmt: skip
        ipc._open("ipcOpenMemHandle", bytes(64), dev, "from_ipc_handle()", " (a hint)")
    assert ipc._open("ipcOpenEventHandle", bytes(64), dev, "event_from_ipc_handle()") == 4242
    assert runtime.calls == [("open event", 1)]


def test_opened_objects_are_released_on_their_device_when_collected(runtime):
    mapping = ipc._Mapping(7, 2)
    event = ipc._OpenedEvent(9, 3)
    del mapping, event
    gc.collect()
    assert sorted(runtime.calls) == [("close", 7, 2), ("destroy", 9, 3)]
