"""Access between CUDA devices of one process: peer access and memory-pool access.

Warp's API, over CuPy's runtime calls:

- ``is_peer_access_supported(target, peer)``: can ``peer`` reach ``target``'s memory
  directly (``cudaDeviceCanAccessPeer``)? False whenever either side is the CPU.
- ``is_peer_access_enabled`` / ``set_peer_access_enabled`` / ``ScopedPeerAccess``:
  switch that access on or off (``cudaDeviceEnablePeerAccess`` with ``peer`` current).
- ``is_mempool_access_supported`` / ``is_mempool_access_enabled`` /
  ``set_mempool_access_enabled`` / ``ScopedMempoolAccess``: access from ``peer`` to the
  allocations of ``target``'s memory pool.

kdsl's pool is CuPy's, whose blocks are ``cudaMalloc`` allocations (not CUDA's
stream-ordered pools), so what lets a peer reach them is CUDA peer access. The two
switches are kept apart, as in Warp: each pair remembers whether peer access and
mempool access were asked for, and CUDA peer access stays on while either is.

The CUDA runtime has no "is peer access on?" query, so the first question about a
pair probes it once (enable, then undo if it was off) and the answer is cached; every
change kdsl makes updates the cache. Cross-device ``copy`` never needs any of this:
``cudaMemcpyPeerAsync`` goes peer to peer where the hardware allows and through the
host otherwise.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslRuntimeError, KdslValueError
from kdsl.runtime.device import Device, cupy, get_device
from kdsl.runtime.mempool import is_mempool_supported

_ALREADY_ENABLED = 704  # cudaErrorPeerAccessAlreadyEnabled
_NOT_ENABLED = 705  # cudaErrorPeerAccessNotEnabled

#: (target ordinal, peer ordinal) -> whether CUDA peer access is on now.
_cuda_state: dict[tuple[int, int], bool] = {}
#: Pairs whose peer access the user turned on (set_peer_access_enabled).
_peer_wanted: set[tuple[int, int]] = set()
#: Pairs whose mempool access the user turned on (set_mempool_access_enabled).
_pool_wanted: set[tuple[int, int]] = set()


def _pair(target: Device, peer: Device) -> tuple[int, int]:
    return target.ordinal, peer.ordinal


def _switch(target: Device, peer: Device, enable: bool) -> bool:
    """Turn CUDA access from ``peer`` to ``target`` on or off; True if it was on before."""
    rt = cupy().cuda.runtime
    saved = rt.getDevice()
    rt.setDevice(peer.ordinal)  # peer access is a property of the accessing device
    try:
        try:
            if enable:
                rt.deviceEnablePeerAccess(target.ordinal)
            else:
                rt.deviceDisablePeerAccess(target.ordinal)
        except rt.CUDARuntimeError as e:
            if e.status == _ALREADY_ENABLED:
                return True
            if e.status == _NOT_ENABLED:
                return False
            action = "enable" if enable else "disable"
            raise KdslRuntimeError(
                f"could not {action} peer access from '{peer}' to '{target}': {e}"
            ) from None
        return not enable
    finally:
        rt.setDevice(saved)


def _cuda_enabled(target: Device, peer: Device) -> bool:
    key = _pair(target, peer)
    if key not in _cuda_state:
        was_on = _switch(target, peer, True)  # the probe: no query exists
        if not was_on:
            _switch(target, peer, False)
        _cuda_state[key] = was_on
        if was_on:  # someone else turned it on: it counts as asked for
            _peer_wanted.add(key)
    return _cuda_state[key]


def _apply(target: Device, peer: Device) -> None:
    """Make CUDA peer access match what the two switches ask for."""
    key = _pair(target, peer)
    want = key in _peer_wanted or key in _pool_wanted
    if _cuda_enabled(target, peer) != want:
        _switch(target, peer, want)
        _cuda_state[key] = want


def _devices(target_device: Any, peer_device: Any) -> tuple[Device, Device]:
    return get_device(target_device), get_device(peer_device)


def is_peer_access_supported(target_device: Any, peer_device: Any) -> bool:
    """True when ``peer_device`` can access ``target_device``'s memory directly.

    Always False when either device is the CPU; True for a device and itself.
    """
    target, peer = _devices(target_device, peer_device)
    if not (target.is_cuda and peer.is_cuda):
        return False
    if target == peer:
        return True
    return bool(cupy().cuda.runtime.deviceCanAccessPeer(peer.ordinal, target.ordinal))


def is_peer_access_enabled(target_device: Any, peer_device: Any) -> bool:
    """True when peer access from ``peer_device`` to ``target_device`` is switched on.

    False when either device is the CPU; True for a CUDA device and itself.
    """
    target, peer = _devices(target_device, peer_device)
    if not (target.is_cuda and peer.is_cuda):
        return False
    if target == peer:
        return True
    _cuda_enabled(target, peer)  # first question: learn the state CUDA has now
    return _pair(target, peer) in _peer_wanted


def set_peer_access_enabled(target_device: Any, peer_device: Any, enable: bool) -> None:
    """Switch direct access from ``peer_device`` to ``target_device``'s memory on or off.

    Enabling raises ``KdslValueError`` when a side is the CPU and ``KdslRuntimeError``
    when the GPUs cannot reach each other; disabling there does nothing (Warp's rules).
    """
    target, peer = _devices(target_device, peer_device)
    if not (target.is_cuda and peer.is_cuda):
        if enable:
            raise KdslValueError(
                f"peer access exists between CUDA devices only, not from '{peer}' to '{target}'"
            )
        return
    if target == peer:
        return
    if not is_peer_access_supported(target, peer):
        if enable:
            raise KdslRuntimeError(f"device '{peer}' cannot access device '{target}' directly")
        return
    (_peer_wanted.add if enable else _peer_wanted.discard)(_pair(target, peer))
    _apply(target, peer)


def is_mempool_access_supported(target_device: Any, peer_device: Any) -> bool:
    """True when ``peer_device`` can access allocations of ``target_device``'s pool."""
    target, peer = _devices(target_device, peer_device)
    return is_mempool_supported(target) and is_peer_access_supported(target, peer)


def is_mempool_access_enabled(target_device: Any, peer_device: Any) -> bool:
    """True when access from ``peer_device`` to ``target_device``'s pool is switched on.

    False when either device is the CPU; True for a CUDA device and itself.
    """
    target, peer = _devices(target_device, peer_device)
    if not (target.is_cuda and peer.is_cuda and is_mempool_supported(target)):
        return False
    if target == peer:
        return True
    return _pair(target, peer) in _pool_wanted


def set_mempool_access_enabled(target_device: Any, peer_device: Any, enable: bool) -> None:
    """Switch access from ``peer_device`` to ``target_device``'s memory pool on or off.

    The same errors as ``set_peer_access_enabled`` (enabling only); turning it off
    leaves peer access on when ``set_peer_access_enabled`` asked for it.
    """
    target, peer = _devices(target_device, peer_device)
    if not (target.is_cuda and peer.is_cuda):
        if enable:
            raise KdslValueError(
                f"memory pool access exists between CUDA devices only, not from '{peer}' to "
                f"'{target}'"
            )
        return
    if target == peer:
        return
    if not is_mempool_access_supported(target, peer):
        if enable:
            raise KdslRuntimeError(f"device '{peer}' cannot access the memory pool of '{target}'")
        return
    (_pool_wanted.add if enable else _pool_wanted.discard)(_pair(target, peer))
    _apply(target, peer)


class ScopedPeerAccess:
    """``with ScopedPeerAccess(target, peer, enable):`` sets peer access for a block,
    restoring the previous setting on exit."""

    def __init__(self, target_device: Any, peer_device: Any, enable: bool) -> None:
        self.target_device = target_device
        self.peer_device = peer_device
        self.enable = enable

    def __enter__(self) -> ScopedPeerAccess:
        self.saved_setting = is_peer_access_enabled(self.target_device, self.peer_device)
        set_peer_access_enabled(self.target_device, self.peer_device, self.enable)
        return self

    def __exit__(self, *exc_info: object) -> None:
        set_peer_access_enabled(self.target_device, self.peer_device, self.saved_setting)


class ScopedMempoolAccess:
    """``with ScopedMempoolAccess(target, peer, enable):`` sets mempool access for a
    block, restoring the previous setting on exit."""

    def __init__(self, target_device: Any, peer_device: Any, enable: bool) -> None:
        self.target_device = target_device
        self.peer_device = peer_device
        self.enable = enable

    def __enter__(self) -> ScopedMempoolAccess:
        self.saved_setting = is_mempool_access_enabled(self.target_device, self.peer_device)
        set_mempool_access_enabled(self.target_device, self.peer_device, self.enable)
        return self

    def __exit__(self, *exc_info: object) -> None:
        set_mempool_access_enabled(self.target_device, self.peer_device, self.saved_setting)
