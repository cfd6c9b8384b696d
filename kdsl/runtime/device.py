"""Devices: where arrays live and kernels run.

A device is named like PyTorch's: ``"cpu"``, ``"cuda"`` (the current CUDA device)
or ``"cuda:N"``. Only ``cpu`` holds arrays today; the ``Device`` object is what
CUDA support will extend. CUDA detection imports CuPy lazily, inside
``is_cuda_available`` only.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslError


class Device:
    """A device by alias (``"cpu"``, ``"cuda:0"``). Compares equal to its alias string."""

    def __init__(self, alias: str) -> None:
        self.alias = alias
        kind, _, ordinal = alias.partition(":")
        self.kind = kind
        self.ordinal = int(ordinal) if ordinal else (0 if kind == "cuda" else -1)

    @property
    def is_cpu(self) -> bool:
        return self.kind == "cpu"

    @property
    def is_cuda(self) -> bool:
        return self.kind == "cuda"

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


_CPU = Device("cpu")
_DEVICES: dict[str, Device] = {"cpu": _CPU}
_default: Device = _CPU
_cuda_count: int | None = None


def cuda_device_count() -> int:
    """Number of CUDA devices CuPy sees (0 without CuPy or a driver). Cached."""
    global _cuda_count
    if _cuda_count is None:
        try:
            import cupy

            _cuda_count = int(cupy.cuda.runtime.getDeviceCount())
        except Exception:  # no cupy, no driver, no device: all mean "no CUDA"
            _cuda_count = 0
    return _cuda_count


def is_cuda_available() -> bool:
    """True when CuPy imports and sees at least one CUDA device."""
    return cuda_device_count() > 0


def get_device(name: Any = None) -> Device:
    """The device named ``name`` (a ``Device``, an alias, or None for the default)."""
    if name is None:
        return _default
    if isinstance(name, Device):
        return name
    if not isinstance(name, str):
        raise KdslError(f"a device is named by a string such as 'cpu', not {name!r}")
    alias = "cuda:0" if name == "cuda" else name
    dev = _DEVICES.get(alias)
    if dev is not None:
        return dev
    kind, _, ordinal = alias.partition(":")
    if kind != "cuda" or not ordinal.isdigit():
        raise KdslError(f"unknown device {name!r}: use 'cpu', 'cuda' or 'cuda:N'")
    if int(ordinal) >= cuda_device_count():
        raise KdslError(f"device {name!r} is not available ({cuda_device_count()} CUDA devices)")
    dev = _DEVICES[alias] = Device(alias)
    return dev


def set_device(name: Any) -> None:
    """Make ``name`` the default device of array constructors and launches."""
    global _default
    _default = get_device(name)


def get_preferred_device() -> Device:
    """The device kdsl uses when none is named (cpu until CUDA arrays land)."""
    return _default


def get_cuda_device_count() -> int:
    """Number of CUDA devices (Warp's name)."""
    return cuda_device_count()


def synchronize() -> None:
    """Wait for all outstanding work on every device (CPU work is synchronous)."""


def synchronize_device(device: Any = None) -> None:
    """Wait for outstanding work on ``device`` (CPU work is synchronous)."""
    get_device(device)
