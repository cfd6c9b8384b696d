"""Cached zero-copy views of framework tensors: the per-call fast path of interop.

Seeing a PyTorch tensor as a kdsl buffer means asking the framework for a NumPy or
CuPy view and checking its dtype, element dims and layout (``views.view_buffer``):
tens of microseconds, paid on every ``from_torch`` call and every launch that takes
a tensor directly. A training loop hands kdsl the same tensors again and again, so
``TensorViews`` keeps, per tensor object, the view built last time with what it was
built from, and hands it back while nothing it depends on changed. Handing back the
same buffer object also lets the launch path reuse its packed descriptors
(``kdsl.runtime.launch_reuse``).

An entry is keyed on the tensor's identity and checked, on every hit, against
everything the view depends on: the tensor object is still the one cached (a weak
reference: a freed tensor's ``id`` may name a new one), and its data pointer,
shape, strides, dtype and device, and the kdsl dtype asked for (the same object),
are unchanged (a tensor re-pointed with ``.data =`` or ``set_``, resized in place,
or seen as another dtype is a miss). The view holds the framework's memory through a *detached* alias,
never through the tensor itself, so an entry dies with its tensor (a weak-reference
callback drops it) and keeps nothing alive longer than the tensor does. At most
``MAX_ENTRIES`` tensors are kept; the oldest entry goes first.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any

from kdsl.ir import types as T
from kdsl.runtime.device import Device

#: Tensors whose views are kept at once (a training step's parameters and buffers).
MAX_ENTRIES = 256

#: ``build(tensor, dtype)``: a fresh view of ``tensor`` (buffer, IR type, device).
Build = Callable[[Any, Any], tuple[Any, T.Type, Device]]


class _Entry:
    __slots__ = ("buf", "dev", "device", "dtype", "kt", "ptr", "ref", "shape", "stride", "tdtype")

    def __init__(self, ref: weakref.ref, ptr: int, shape: Any, stride: tuple, tdtype: Any,
                 device: Any, dtype: Any, view: tuple[Any, T.Type, Device]) -> None:  # fmt: skip
        self.ref, self.ptr, self.shape, self.stride = ref, ptr, shape, stride
        self.tdtype, self.device, self.dtype = tdtype, device, dtype
        self.buf, self.kt, self.dev = view


class TensorViews:
    """Views of PyTorch-like tensors (``data_ptr``, ``shape``, ``stride()``, ``dtype``,
    ``device``) by tensor identity, checked on every hit (see the module docstring)."""

    def __init__(self, build: Build, max_entries: int = MAX_ENTRIES) -> None:
        self.build = build
        self.max_entries = max_entries
        self.entries: dict[int, _Entry] = {}
        #: Calls answered from the cache (for tests and benchmarks).
        self.hits = 0

    def view(self, t: Any, dtype: Any = None) -> tuple[Any, T.Type, Device]:
        """``build(t, dtype)``, or the view built for ``t`` before when still valid."""
        key = id(t)
        e = self.entries.get(key)
        if (
            e is not None
            and e.ref() is t
            and e.ptr == t.data_ptr()
            and e.shape == t.shape
            and e.stride == t.stride()
            and e.tdtype is t.dtype
            and e.device == t.device
            and e.dtype is dtype
        ):
            self.hits += 1
            return e.buf, e.kt, e.dev
        view = self.build(t, dtype)  # raises for bad input: nothing is cached then
        try:
            ref = weakref.ref(t, self._dropper(key))
        except TypeError:  # not weak-referenceable: never cached
            return view
        entries = self.entries
        if key not in entries and len(entries) >= self.max_entries:
            del entries[next(iter(entries))]  # the oldest
        entries[key] = _Entry(
            ref, t.data_ptr(), t.shape, t.stride(), t.dtype, t.device, dtype, view
        )
        return view

    def _dropper(self, key: int) -> Callable[[weakref.ref], None]:
        entries = self.entries

        def drop(ref: weakref.ref) -> None:
            e = entries.get(key)
            if e is not None and e.ref is ref:
                del entries[key]

        return drop

    def clear(self) -> None:
        """Forget every view."""
        self.entries.clear()
