"""Devices: where arrays live and kernels run.

A device is named like PyTorch's: ``"cpu"``, ``"cuda"`` (the *current* CUDA
device: ``cuda:0`` unless ``set_device``/``ScopedDevice`` chose another) or
``"cuda:N"``. CuPy is imported lazily, the first time a CUDA device is asked
for, so ``import kdsl`` never loads it. The default device of constructors and
launches stays ``cpu`` until ``set_device`` changes it.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from kdsl.errors import KdslError

_SPELLINGS = "'cpu', 'cuda' (the current CUDA device) or 'cuda:N' (N = 0, 1, ...)"


class Device:
    """A device by alias (``"cpu"``, ``"cuda:0"``). Compares equal to its alias string."""

    def __init__(self, alias: str) -> None:
        self.alias = alias
        kind, _, ordinal = alias.partition(":")
        self.kind = kind
        self.ordinal = int(ordinal) if ordinal else (0 if kind == "cuda" else -1)

    @property
    def is_cpu(self) -> bool:
        """True for the host."""
        return self.kind == "cpu"

    @property
    def is_cuda(self) -> bool:
        """True for a CUDA GPU."""
        return self.kind == "cuda"

    def _props(self) -> dict:
        return cupy().cuda.runtime.getDeviceProperties(self.ordinal)

    @property
    def name(self) -> str:
        """The GPU's product name (``"NVIDIA H100 80GB HBM3"``), or ``"CPU"``."""
        if self.is_cpu:
            return "CPU"
        raw = self._props()["name"]
        return raw.decode() if isinstance(raw, bytes) else str(raw)

    @property
    def arch(self) -> int:
        """Compute capability as an int (90 for sm_90); 0 on the CPU."""
        if self.is_cpu:
            return 0
        p = self._props()
        return int(p["major"]) * 10 + int(p["minor"])

    @property
    def total_memory(self) -> int:
        """Bytes of memory on the device (physical RAM for the CPU)."""
        return self._memory("SC_PHYS_PAGES", 1)

    @property
    def free_memory(self) -> int:
        """Bytes the driver reports free now (CuPy's pool holds some it does not count)."""
        return self._memory("SC_AVPHYS_PAGES", 0)

    def _memory(self, host_pages: str, field: int) -> int:
        # ``host_pages``: the sysconf name on the CPU; ``field``: free 0 or total 1 of mem_info.
        if self.is_cpu:
            return _host_pages(host_pages)
        with cupy().cuda.Device(self.ordinal) as d:
            return int(d.mem_info[field])

    @property
    def stream(self) -> Any:
        """The device's current ``Stream`` (a ``KdslError`` on the CPU)."""
        from kdsl.runtime.stream import get_stream

        return get_stream(self)

    def can_access(self, other: Any) -> bool:
        """True when kernels on this device can read ``other``'s memory directly."""
        o = get_device(other)
        if o == self:
            return True
        if self.is_cpu or o.is_cpu:
            return False
        return bool(cupy().cuda.runtime.deviceCanAccessPeer(self.ordinal, o.ordinal))

    def make_current(self) -> None:
        """Make this the current CUDA device of the calling thread (no-op on the CPU)."""
        if self.is_cuda:
            cupy().cuda.Device(self.ordinal).use()

    def __str__(self) -> str:
        return self.alias

    def __repr__(self) -> str:
        return f"Device({self.alias!r})"

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Device):
            return self.alias == other.alias
        if isinstance(other, str):
            try:
                return get_device(other).alias == self.alias
            except KdslError:
                return False
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self.alias)


def _host_pages(name: str) -> int:
    try:
        return int(os.sysconf(name) * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # not every OS names these
        return 0


def cupy() -> Any:
    """The CuPy module, imported on first use (``import kdsl`` never loads it)."""
    import cupy

    return cupy


_CPU = Device("cpu")
_DEVICES: dict[str, Device] = {"cpu": _CPU}
_default: Device = _CPU
_current_cuda = 0  # the ordinal "cuda" means


_COUNTER: list = []  # the cuda backend's device_count, once imported


def cuda_device_count() -> int:
    """Number of CUDA devices CuPy sees (0 without CuPy or a driver). Cached."""
    if not _COUNTER:
        # Imported on first use: ``import kdsl`` loads no backend package. Kept, since
        # hot paths (a zero fill, a launch) ask, and an import statement costs microseconds.
        from kdsl.backends.cuda.devices import device_count

        _COUNTER.append(device_count)
    return _COUNTER[0]()


def cuda_initialized() -> bool:
    """True once CuPy is loaded and sees a GPU: only then can CUDA work be pending."""
    return "cupy" in sys.modules and cuda_device_count() > 0


def is_cuda_available() -> bool:
    """True when CuPy imports and sees at least one CUDA device."""
    return cuda_device_count() > 0


def get_cuda_device_count() -> int:
    """Number of CUDA devices (Warp's name)."""
    return cuda_device_count()


def get_device(name: Any = None) -> Device:
    """The device named ``name`` (a ``Device``, an alias, or None for the default)."""
    if name is None:
        return _default
    if isinstance(name, Device):
        return name
    if not isinstance(name, str):
        raise KdslError(f"a device is named by a string ({_SPELLINGS}), not {name!r}")
    dev = _DEVICES.get(name)
    if dev is not None:
        return dev
    kind, colon, ordinal = name.partition(":")
    if kind != "cuda" or (colon and not ordinal.isdigit()):
        raise KdslError(f"unknown device {name!r}: use {_SPELLINGS}")
    n = cuda_device_count()
    index = int(ordinal) if colon else _current_cuda
    if index >= n:
        have = "no CUDA devices" if n == 0 else f"CUDA devices cuda:0 to cuda:{n - 1}"
        raise KdslError(f"device {name!r} is not available: this machine has {have}")
    alias = f"cuda:{index}"
    dev = _DEVICES.get(alias)
    if dev is None:
        dev = _DEVICES[alias] = Device(alias)
    return dev


def get_cuda_devices() -> list[Device]:
    """Every CUDA device, ``cuda:0`` first (empty without CUDA)."""
    return [get_device(f"cuda:{i}") for i in range(cuda_device_count())]


def get_cuda_device(ordinal: int | None = None) -> Device:
    """The CUDA device ``ordinal``, or the current CUDA device when None (Warp's name)."""
    if ordinal is None:
        return get_device("cuda")
    if not isinstance(ordinal, int) or isinstance(ordinal, bool):
        raise KdslError(f"get_cuda_device takes an int ordinal, not {ordinal!r}")
    return get_device(f"cuda:{ordinal}")


def is_cpu_available() -> bool:
    """True: kdsl always runs kernels on the CPU (the ``cpu`` or ``interp`` backend)."""
    return True


def get_devices() -> list[Device]:
    """Every device: the CPU, then each CUDA device (Warp's order)."""
    return [_CPU, *get_cuda_devices()]


def is_device_available(device: Any) -> bool:
    """True when ``device`` (a ``Device`` or an alias) is one of ``get_devices()``."""
    if isinstance(device, str):
        try:
            device = get_device(device)
        except KdslError:
            return False
    return device in get_devices()


def set_device(name: Any) -> None:
    """Make ``name`` the default device; a CUDA device also becomes the current one."""
    global _default, _current_cuda
    dev = get_device(name)
    _default = dev
    if dev.is_cuda:
        _current_cuda = dev.ordinal
        dev.make_current()


def get_preferred_device() -> Device:
    """The current CUDA device when there is one, else the CPU (Warp's preference)."""
    return get_device("cuda") if is_cuda_available() else _CPU


class ScopedDevice:
    """``with ScopedDevice("cuda:1"):`` makes a device the default (and current) for a block."""

    def __init__(self, device: Any) -> None:
        self.device = get_device(device)

    def __enter__(self) -> Device:
        self._saved = (_default, _current_cuda)
        self._saved_cupy = cupy().cuda.runtime.getDevice() if self.device.is_cuda else None
        set_device(self.device)
        return self.device

    def __exit__(self, *exc_info: object) -> None:
        global _default, _current_cuda
        _default, _current_cuda = self._saved
        if self._saved_cupy is not None:
            cupy().cuda.runtime.setDevice(self._saved_cupy)
