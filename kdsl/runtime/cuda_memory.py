"""Device buffers: the CuPy side of ``kdsl.array`` and the copies between devices.

A CUDA array's buffer is a ``cupy.ndarray`` from CuPy's memory pool. Every CuPy
operation kdsl performs runs inside ``scope(device)``: the device is current
and its kdsl stream is CuPy's current stream, so array methods, copies and
kernel launches form one ordered queue per device. CuPy is imported here
only when a CUDA device is used.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.runtime import allocators
from kdsl.runtime.device import Device, cuda_device_count, cupy
from kdsl.runtime.graphs.state import refuse_host_read, refuse_upload
from kdsl.runtime.mempool import note_allocation
from kdsl.runtime.stream import Stream, current_stream, get_stream


def xp(device: Device) -> Any:
    """NumPy for the CPU, CuPy for CUDA devices."""
    return np if device.is_cpu else cupy()


def is_cuda_buffer(obj: Any) -> bool:
    """True for objects that expose ``__cuda_array_interface__`` (CuPy, PyTorch, Numba...)."""
    try:
        return hasattr(obj, "__cuda_array_interface__")
    except Exception:  # a property that raises for a CPU object is a "no"
        return False


def _human(nbytes: int) -> str:
    size = float(nbytes)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if size < 1024 or unit == "TiB":
            return f"{size:.0f} {unit}" if unit == "bytes" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{nbytes} bytes"


def _oom(device: Device, nbytes: int | None, err: BaseException) -> KdslError:
    what = f"{nbytes} bytes ({_human(nbytes)})" if nbytes is not None else "memory"
    return KdslError(
        f"out of memory on '{device}': cannot allocate {what}. CuPy said: {err}. Free arrays "
        f"you no longer need or use a smaller size"
    )


class scope:
    """``with scope(device[, stream]):`` runs CuPy work on ``device`` and its stream.

    A no-op for the CPU. Out-of-memory errors inside become a ``KdslError``.
    """

    __slots__ = ("device", "stream", "_dev", "_nbytes")

    def __init__(self, device: Device, stream: Stream | None = None, nbytes: int | None = None):
        self.device = device
        self.stream = stream
        self._nbytes = nbytes

    def __enter__(self) -> Stream | None:
        if self.device.is_cpu:
            return None
        cp = cupy()
        self._dev = cp.cuda.Device(self.device.ordinal)
        self._dev.__enter__()
        if self.stream is None:
            self.stream = get_stream(self.device)
        self.stream.cupy.__enter__()
        return self.stream

    def __exit__(self, *exc_info: object) -> None:
        if self.device.is_cpu:
            return
        self.stream.cupy.__exit__(*exc_info)
        self._dev.__exit__(*exc_info)
        exc = exc_info[1]
        if exc is not None and isinstance(exc, cupy().cuda.memory.OutOfMemoryError):
            raise _oom(self.device, self._nbytes, exc) from None


def empty(shape: tuple[int, ...], dtype: np.dtype, device: Device) -> Any:
    """An uninitialized buffer on ``device`` (a NumPy or CuPy array)."""
    if device.is_cpu:
        return allocators.host_empty(shape, dtype, device)
    nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    with scope(device, nbytes=nbytes):
        buf = allocators.cuda_empty(shape, dtype, device, nbytes)
        note_allocation(device.ordinal)
        return buf


def zeros_like(buf: Any, device: Device) -> Any:
    """A zero buffer shaped like ``buf`` on ``device``."""
    out = empty(buf.shape, buf.dtype, device)
    if device.is_cpu:
        out.fill(0)
    else:
        zero_async(out, device)
    return out


_RUNTIME: list = []


def zero_async(buf: Any, device: Device) -> None:
    """Zero the C-contiguous CUDA buffer ``buf`` with one ``cudaMemsetAsync`` on the
    device's current kdsl stream (a CuPy fill is a kernel launch behind Python dispatch
    and a ``scope``)."""
    nbytes = buf.nbytes
    if not nbytes:
        return
    if not _RUNTIME:
        from cupy_backends.cuda.api import runtime

        _RUNTIME.append(runtime)
    stream = current_stream(device)
    if cuda_device_count() == 1:  # the only device is the current one
        _RUNTIME[0].memsetAsync(buf.data.ptr, 0, nbytes, stream.cuda_stream)
        return
    with scope(device, stream):
        _RUNTIME[0].memsetAsync(buf.data.ptr, 0, nbytes, stream.cuda_stream)


def to_host(buf: Any, device: Device) -> np.ndarray:
    """A NumPy copy of a CUDA buffer; waits for the device's stream (the seeds' rule)."""
    refuse_host_read(device, "reading device data on the host (numpy(), an element, print)")
    with scope(device):
        return buf.get()  # copies on the current (kdsl) stream and synchronizes it


def from_host(data: np.ndarray, device: Device) -> Any:
    """``data`` copied to ``device`` (enqueued on its stream)."""
    refuse_upload(device, "uploading host data")
    out = empty(data.shape, data.dtype, device)
    with scope(device):
        out.set(np.ascontiguousarray(data))
    return out


def wrap_cuda(obj: Any) -> tuple[Any, Device]:
    """A zero-copy CuPy view of a ``__cuda_array_interface__`` object, and its device."""
    from kdsl.runtime.device import get_device

    cp = cupy()
    owner = _owning_device(cp, obj.__cuda_array_interface__["data"][0])
    if owner < 0:  # memory the driver does not know (or a null pointer): CuPy's label
        if isinstance(obj, cp.ndarray):  # as it is: asarray would copy it to the current GPU
            return obj, get_device(f"cuda:{obj.device.id}")
        arr = cp.asarray(obj)
        return arr, get_device(f"cuda:{arr.device.id}")
    # Made with the owner current: CuPy copies an interface object of another device
    # to the current one (on 4 GPUs a torch tensor of cuda:1, with cuda:3 current,
    # came back as a copy on cuda:3, so a launch's writes never reached the tensor).
    with cp.cuda.Device(owner):
        arr = cp.asarray(obj)
    return arr, get_device(f"cuda:{owner}")


def _owning_device(cp: Any, ptr: int) -> int:
    # The GPU that holds the memory, asked of the driver; -1 if it does not know.
    if not ptr:
        return -1
    try:
        return int(cp.cuda.runtime.pointerGetAttributes(ptr).device)
    except cp.cuda.runtime.CUDARuntimeError:
        return -1


def _flat_view(buf: Any, inner: tuple[int, ...]) -> Any:
    # One row per element, when that is a view of ``buf`` (not a copy).
    return buf.reshape(-1, *inner) if buf.flags.c_contiguous else None


def _memcpy(dst: Any, dst_dev: Device, src: Any, src_dev: Device, stream: Stream) -> None:
    """Enqueue a raw copy of contiguous ``src`` into contiguous ``dst`` on ``stream``."""
    rt = cupy().cuda.runtime
    nbytes = src.nbytes
    if nbytes == 0:
        return
    s = stream.cuda_stream
    if dst_dev.is_cpu:
        rt.memcpyAsync(dst.ctypes.data, src.data.ptr, nbytes, rt.memcpyDeviceToHost, s)
    elif src_dev.is_cpu:
        rt.memcpyAsync(dst.data.ptr, src.ctypes.data, nbytes, rt.memcpyHostToDevice, s)
    elif dst_dev == src_dev:
        rt.memcpyAsync(dst.data.ptr, src.data.ptr, nbytes, rt.memcpyDeviceToDevice, s)
    else:  # peer access when the GPUs have it, staged by the driver otherwise
        rt.memcpyPeerAsync(dst.data.ptr, dst_dev.ordinal, src.data.ptr, src_dev.ordinal, nbytes, s)


def upload_bytes(address: int, data: bytes, device: Device) -> None:
    """Enqueue a copy of the host bytes ``data`` to device address ``address`` on
    ``device``'s current stream (staged by the driver before this returns, so ``data``
    may go at once): a small upload (an object record) without the array checks and
    the stream bookkeeping of ``copy_elements``."""
    refuse_upload(device, "an object record write")
    if not data:
        return
    s = get_stream(device)
    rt = cupy().cuda.runtime
    keep = bytes(data)  # (immutable: its address is read without NumPy)
    src = ctypes.cast(ctypes.c_char_p(keep), ctypes.c_void_p).value
    if cuda_device_count() == 1:  # the only device is the current one: no device scope
        rt.memcpyAsync(address, src, len(keep), rt.memcpyHostToDevice, s.cuda_stream)
        return
    with scope(device, s):
        rt.memcpyAsync(address, src, len(keep), rt.memcpyHostToDevice, s.cuda_stream)


def copy_elements(
    dest: Any,
    dest_dev: Device,
    dest_offset: int,
    src: Any,
    src_dev: Device,
    src_offset: int,
    count: int,
    inner: tuple[int, ...],
    stream: Stream | None = None,
) -> None:
    """Copy ``count`` elements (rows of ``inner`` components) between buffers, row-major.

    The range must be valid (callers check). With a CUDA side the copy is
    enqueued on ``stream``: by default the destination's current stream when
    it is on a GPU, else the source's. That stream first waits for the other
    device's current stream, and afterwards both devices' current streams wait
    for it, so the copy is ordered with everything before and after it on both
    devices. Copies to the CPU are asynchronous: call ``kdsl.synchronize()``
    before reading the destination with ``numpy()``.
    """
    if count == 0:
        return
    if dest_dev.is_cpu and src_dev.is_cpu:
        _copy_cpu(dest, dest_offset, src, src_offset, count, inner)
        return
    if dest_dev.is_cpu or src_dev.is_cpu:
        refuse_upload(dest_dev if dest_dev.is_cuda else src_dev, f"copy() from '{src_dev}' to '{dest_dev}'")
    s = stream or get_stream(dest_dev if dest_dev.is_cuda else src_dev)
    if s.device not in (dest_dev, src_dev):
        raise KdslError(
            f"copy() from '{src_dev}' to '{dest_dev}' cannot run on a stream of '{s.device}'"
        )
    others = [get_stream(d) for d in {dest_dev, src_dev} if d.is_cuda]
    others = [o for o in others if o is not s]
    for o in others:
        s.wait_stream(o)
    # 1. The source range as one contiguous block, made on the source's side.
    if src_dev.is_cpu:
        part = np.ascontiguousarray(src.reshape(-1, *inner)[src_offset : src_offset + count])
    else:
        ps = s if s.device == src_dev else get_stream(src_dev)
        with scope(src_dev, ps):
            flat = src.reshape(-1, *inner)
            part = cupy().ascontiguousarray(flat[src_offset : src_offset + count])
        s.wait_stream(ps)  # a no-op when ps is s
    # 2. Into the destination range, or a staging block when the destination is strided.
    region = _flat_view(dest, inner)
    if region is not None:
        target = region[dest_offset : dest_offset + count]
    elif dest_dev.is_cpu:
        target = np.empty(part.shape, part.dtype)
    else:
        target = empty(part.shape, part.dtype, dest_dev)
    with scope(s.device, s):
        _memcpy(target, dest_dev, part, src_dev, s)
    # 3. Scatter the staging block into a strided destination, on the destination's side.
    if region is None:
        if dest_dev.is_cpu:
            s.synchronize()  # the host reads the staging block now
            _copy_cpu(dest, dest_offset, target, 0, count, inner)
        else:
            sd = s if s.device == dest_dev else get_stream(dest_dev)
            sd.wait_stream(s)
            with scope(dest_dev, sd):
                flat = dest.reshape(-1, *inner)  # a copy, written back whole
                flat[dest_offset : dest_offset + count] = target
                dest[...] = flat.reshape(dest.shape)
    for o in others:
        o.wait_stream(s)


def _copy_cpu(dest: Any, dest_offset: int, src: Any, src_offset: int, n: int, inner: tuple) -> None:
    flat_src = src.reshape(-1, *inner)
    flat_dest = dest.reshape(-1, *inner)
    flat_dest[dest_offset : dest_offset + n] = flat_src[src_offset : src_offset + n]
    if not np.shares_memory(flat_dest, dest):  # strided dest: reshape made a copy
        dest[...] = flat_dest.reshape(dest.shape)


def transfer(buf: Any, src_dev: Device, dest_dev: Device) -> Any:
    """A contiguous copy of ``buf`` on ``dest_dev`` (ordered on both devices' streams)."""
    out = empty(buf.shape, buf.dtype, dest_dev)
    inner = buf.shape[1:] if buf.ndim else ()
    n = buf.shape[0] if buf.ndim else 1
    copy_elements(out, dest_dev, 0, buf.reshape(n, *inner), src_dev, 0, n, tuple(inner))
    if dest_dev.is_cpu:
        # A host copy is read at once by the caller: wait for the copy's stream.
        get_stream(src_dev).synchronize()
    return out
