"""The per-device object table: where runtime objects keep the records kernels read.

A geometry object (``Bvh``, ``Mesh``...) is named in kernels by a ``uint64`` id, the
address of its *record* on its device (see ``kdsl.ir.records``): a struct holding
the object's array descriptors and scalars, first of all a tag that says which kind
of object it is. This module allocates records, writes them and frees them.

Records come from slabs that are never given back to the allocator: a freed record's
tag is zeroed and its slot recycled oldest first, so a stale id still points at
readable memory and a debug build's ``kd.check_record`` reports it instead of reading
freed memory. ``owner_of`` tells which live object an id belongs to (the launch
checks an id's device with it).
"""

from __future__ import annotations

import collections
import ctypes
import struct
import threading
import weakref
from typing import Any

import numpy as np

from kdsl.errors import KdslLaunchError
from kdsl.ir import types as T
from kdsl.ir.ops_debug import plausible_record_id, set_host_record_memory
from kdsl.ir.records import record_dtype, record_tag
from kdsl.runtime import alloc
from kdsl.runtime.array import array
from kdsl.runtime.cuda_memory import upload_bytes
from kdsl.runtime.device import Device, get_device

#: Bytes per slab; records are rounded up to a multiple of ``_GRAIN``.
_SLAB = 1 << 16
_GRAIN = 64


class _DeviceTable:
    """The record slabs and free slots of one device."""

    def __init__(self, device: Device) -> None:
        self.device = device
        self.slabs: list[array] = []  # kept alive for the life of the process
        self.free: dict[int, collections.deque[int]] = collections.defaultdict(collections.deque)
        self.next: tuple[int, int] = (0, 0)  # (slab base address, next free offset)

    def allocate(self, size: int) -> int:
        size = -(-size // _GRAIN) * _GRAIN
        if size > _SLAB:
            raise KdslLaunchError(f"an object record of {size} bytes exceeds {_SLAB}")
        slots = self.free[size]
        if slots:
            return slots.popleft()
        base, used = self.next
        if not self.slabs or used + size > _SLAB:
            slab = alloc.zeros(_SLAB, dtype=T.U8, device=self.device)
            self.slabs.append(slab)
            base, used = slab.ptr, 0
        self.next = (base, used + size)
        if not plausible_record_id(base + used):  # kd.check_record would refuse its id
            raise KdslLaunchError(f"an object record at {base + used:#x} on {self.device}: "
                                  "not an address kd.check_record accepts")  # fmt: skip
        return base + used

    def write(self, address: int, data: bytes) -> None:
        if self.device.is_cpu:
            ctypes.memmove(address, data, len(data))
            return
        self._locate(address)  # (refuses an address outside the slabs)
        upload_bytes(address, data, self.device)

    def _locate(self, address: int) -> tuple[array, int]:
        for slab in self.slabs:
            if slab.ptr <= address < slab.ptr + _SLAB:
                return slab, address - slab.ptr
        raise KdslLaunchError(f"address {address:#x} is not an object record of {self.device}")


_tables: dict[str, _DeviceTable] = {}
_owners: dict[int, tuple[weakref.ref, str, str]] = {}
_lock = threading.Lock()


def _in_host_slabs(address: int) -> bool:
    """Whether ``address`` lies in a host record slab (readable, whatever it holds)."""
    table = _tables.get("cpu")
    return table is not None and any(s.ptr <= address < s.ptr + _SLAB for s in table.slabs)


set_host_record_memory(_in_host_slabs)


def _table(device: Device) -> _DeviceTable:
    table = _tables.get(device.alias)
    if table is None:
        table = _tables[device.alias] = _DeviceTable(device)
    return table


def pack_record(t: T.StructType, fields: dict[str, Any]) -> bytes:
    """The bytes of a record of struct type ``t`` (its tag is ``t``'s name's).

    ``fields`` maps each field but the tag (the first) to its value: a ``kdsl.array``
    for an array field (its descriptor is written: address, shape, byte strides), a
    number or vector otherwise. (Array descriptors, Python ints in integer fields and
    Python floats in float fields are packed by ``struct``, the rest by NumPy: a
    record write is on the path of every geometry object's construction.)
    """
    template, packers, dt = _packer(t)
    buf = bytearray(template)
    for name, offset, words, scalar in packers:
        value = fields[name]
        if words:
            if value.ndim * 2 + 1 == words.size // 8:
                words.pack_into(buf, offset, value.ptr or 0, *value.shape, *value.strides)
                continue
        elif scalar is not None and type(value) in scalar[1]:
            try:
                scalar[0].pack_into(buf, offset, value)
                continue
            except (struct.error, OverflowError):  # out of the field's range: NumPy's cast
                pass
        one = np.zeros((), dtype=dt)  # NumPy's casts and errors, as before
        one[name] = [value.ptr or 0, *value.shape, *value.strides] if words else np.asarray(value)
        size = one.dtype.fields[name][0].itemsize
        buf[offset : offset + size] = one.tobytes()[offset : offset + size]
    return bytes(buf)


#: Per record type, by identity (hashing a struct type hashes all its fields): (the
#: type, its bytes with the tag and zeros, one packer per other field, its dtype).
_packers: dict[int, tuple[T.StructType, bytes, list, np.dtype]] = {}
#: The Python types ``struct`` packs exactly as NumPy casts them, per field kind.
_EXACT = {"i": (int,), "u": (int,), "f": (float,)}


def _packer(t: T.StructType) -> tuple[bytes, list, np.dtype]:
    """(template, [(field, offset, descriptor struct or None, (scalar struct, exact
    Python types) or None)], record dtype) of record type ``t``, made once."""
    hit = _packers.get(id(t))
    if hit is not None and hit[0] is t:
        return hit[1], hit[2], hit[3]
    dt = record_dtype(t)
    rec = np.zeros((), dtype=dt)
    rec[t.fields[0][0]] = record_tag(t.name)
    packers = []
    for name, ft in t.fields[1:]:
        fdt, offset = dt.fields[name][0], dt.fields[name][1]
        words = struct.Struct(f"<{fdt.shape[0]}q") if isinstance(ft, T.ArrayType) else None
        scalar = None
        if words is None and fdt.shape == () and fdt.kind in _EXACT and fdt.byteorder in "=<|":
            scalar = (struct.Struct("<" + fdt.char), _EXACT[fdt.kind])
        packers.append((name, offset, words, scalar))
    _packers[id(t)] = (t, rec.tobytes(), packers, dt)
    return rec.tobytes(), packers, dt


class ObjectRecord:
    """One object's record on its device: allocated on creation, rewritten by ``write``,
    its tag zeroed and slot recycled by ``free`` (or when the owner is collected)."""

    def __init__(self, owner: Any, t: T.StructType, kind: str, device: Any) -> None:
        self.type, self.kind = t, kind
        self.device = get_device(device)
        size = len(_packer(t)[0])  # (record_dtype(t).itemsize, without hashing t)
        with _lock:
            self.id = _table(self.device).allocate(size)
            _owners[self.id] = (weakref.ref(owner), kind, self.device.alias)
        self._finalizer = weakref.finalize(owner, _release, self.device, self.id, size)

    def write(self, fields: dict[str, Any]) -> None:
        """Write the record from ``fields`` (see ``pack_record``)."""
        data = pack_record(self.type, fields)
        with _lock:
            _table(self.device).write(self.id, data)

    def free(self) -> None:
        """Zero the tag and recycle the slot now (idempotent)."""
        self._finalizer()


def _release(device: Device, address: int, size: int) -> None:
    with _lock:
        table = _table(device)
        table.write(address, bytes(8))  # the tag: a stale id now fails kd.check_record
        table.free[-(-size // _GRAIN) * _GRAIN].append(address)
        _owners.pop(address, None)


def owner_of(object_id: int) -> tuple[Any, str, str] | None:
    """(owner object, kind, device alias) of a live object's id, or None."""
    hit = _owners.get(int(object_id))
    if hit is None:
        return None
    owner = hit[0]()
    return None if owner is None else (owner, hit[1], hit[2])


def foreign_id(object_id: int, device: str) -> str | None:
    """Why ``object_id`` cannot be used on ``device`` (it is a live object's id on another
    device), or None (an object of this device, or no live object's id at all)."""
    hit = _owners.get(object_id)
    if hit is None or hit[2] == device:
        return None
    return f"{object_id:#x} is the id of a {hit[1]} on device '{hit[2]}', not on '{device}'"
