"""Zero many arrays at once: ``Tape.zero()``'s gradients in one pass per device.

A taped simulation step ends with ``tape.zero()`` over every gradient it used (about a
hundred arrays for the ``throw`` scene), and zeroing them one by one costs a CuPy fill
kernel (with its Python dispatch) per array on a GPU. ``zero_arrays`` keeps, for a
list of arrays, a plan of what zeroing them takes, and does it in as few calls as it
can:

- on a CUDA device, one launch of ``_zero_words`` over a table of (address, 32-bit
  words) of every array that is one contiguous span of whole words (the table is
  uploaded once per plan), on the device's current stream, as ``array.zero_`` is;
- on the CPU, a fill of each contiguous span's bytes (no per-array Python checks);
- everything else (a strided view, a span of odd size or alignment, an open graph
  capture) through ``array.zero_``.

Plans are kept by the arrays' identities, in order, and hold the arrays weakly: a plan
serves a list only while every array it was made for is alive and in its place, so a
new tape over the same gradients (a simulation that tapes each step afresh) reuses it,
and an array freed and replaced by another at the same address never is. Lists shorter
than ``MIN_BATCH`` on a CUDA device zero array by array (the zero kernel is compiled on
first use).
"""

from __future__ import annotations

import ctypes
import functools
import operator
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.frontend.api import kernel, tid
from kdsl.runtime.array import array
from kdsl.runtime.device import Device
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.launch import launch
from kdsl.runtime.stream import get_stream
from kdsl.types import int32, uint32, uint64

#: Device kinds whose arrays the zero kernel clears (the cpu's are ``memset``).
KERNEL_KINDS = frozenset({"cuda"})
#: Fewest arrays on one CUDA device worth a launch of the zero kernel.
MIN_BATCH = 4
#: Threads per array of the zero kernel, at most (each then stores every this-many words).
MAX_WIDTH = 1 << 17
#: Largest array (in 32-bit words) the zero kernel takes (its indices are 32-bit ints,
#: and a thread's last index plus ``MAX_WIDTH`` must not overflow).
MAX_WORDS = (1 << 31) - 1 - MAX_WIDTH


@kernel
def _zero_words(ptrs: array(dtype=uint64), words: array(dtype=int32), width: int):
    a, j = tid()
    n = words[a]
    span = array(ptr=ptrs[a], shape=(n,), dtype=uint32)
    k = j
    while k < n:
        span[k] = uint32(0)
        k += width


class _Plan:
    """What zeroing one list of arrays takes: the calls, and the arrays (held weakly)."""

    __slots__ = ("refs", "steps")

    def __init__(self, refs: list, steps: list) -> None:
        self.refs = refs
        self.steps = steps


#: Plans by the arrays' ids (in order), the most recently made last; a plan serves a list
#: only while every array it was made for is alive and in its place (so an id reused by
#: a new array is never mistaken for the old one).
_PLANS: dict[tuple[int, ...], _Plan] = {}
#: Plans kept (a tape per step of a simulation zeroes the same gradients every step).
MAX_PLANS = 8
#: Plans made so far (for tests and benchmarks).
made = 0


def zero_arrays(arrays: Sequence[array]) -> None:
    """Set every element of every array in ``arrays`` to zero, with the plan made for
    this very list of arrays when there is one (see the module docstring)."""
    if graphs.ACTIVE:  # captures have their own fill paths
        for a in arrays:
            a.zero_()
        return
    key = tuple(map(id, arrays))
    plan = _PLANS.get(key)
    if plan is None or not all(map(operator.is_, map(operator.call, plan.refs), arrays)):
        plan = _make_plan(key, arrays)
    for step in plan.steps:
        step()


def forget_plans() -> None:
    """Drop every plan (and the device tables they hold)."""
    _PLANS.clear()


def _make_plan(key: tuple[int, ...], arrays: Sequence[array]) -> _Plan:
    global made
    steps: list = []
    by_device: dict[Device, list[tuple[array, tuple[int, int]]]] = {}
    for a in arrays:
        span = a.memory_span()
        if span is None:
            steps.append(_zero_later(a))
        elif span[1] == 0:
            continue
        elif a.device.kind not in KERNEL_KINDS:
            steps.append(_memset(*span) if a.device.is_cpu else _zero_later(a))
        elif span[0] % 4 == 0 and span[1] % 4 == 0 and span[1] // 4 <= MAX_WORDS:
            by_device.setdefault(a.device, []).append((a, span))
        else:
            steps.append(_zero_later(a))
    for dev, items in by_device.items():
        if len(items) < MIN_BATCH:
            steps += [_zero_later(a) for a, _ in items]
        else:
            steps.append(zero_spans_launch(dev, [span for _, span in items]))
            if dev.is_cuda:  # the table is in place before any stream runs it
                get_stream(dev).synchronize()
    plan = _Plan([weakref.ref(a) for a in arrays], steps)
    _PLANS.pop(key, None)
    while len(_PLANS) >= MAX_PLANS:
        del _PLANS[next(iter(_PLANS))]
    _PLANS[key] = plan
    made += 1
    return plan


def _zero_later(a: array) -> Callable[[], None]:
    """``a.zero_`` without holding ``a``: a kept plan must not keep gradients alive (it
    runs only after checking that every array it was made for is alive)."""
    ref = weakref.ref(a)
    return lambda: ref().zero_()


def _memset(addr: int, nbytes: int) -> Callable[[], Any]:
    """Zero ``nbytes`` of host memory at ``addr`` (a NumPy fill of a byte view: a third of
    the cost of a ``ctypes.memset`` call)."""
    view = np.frombuffer((ctypes.c_ubyte * nbytes).from_address(addr), dtype=np.uint8)
    return functools.partial(view.fill, 0)


def zero_spans_launch(dev: Device, spans: Sequence[tuple[int, int]]) -> Callable[[], None]:
    """A call zeroing ``spans`` ((address, bytes): 4-byte aligned multiples of 4 bytes, at
    most ``MAX_WORDS`` words each) on ``dev`` with one launch of the zero kernel, on the
    device's current stream. The table is uploaded now, once."""
    bad = [(p, n) for p, n in spans if p % 4 or n % 4 or not 0 < n // 4 <= MAX_WORDS]
    if bad or not spans:
        raise KdslError(
            f"zero_spans_launch: spans must be 4-byte aligned, non-empty multiples of 4 bytes "
            f"of at most {MAX_WORDS} words; got {bad[0] if bad else 'no spans'}"
        )
    ptrs = array(np.array([p for p, _ in spans], dtype=np.uint64), dtype=uint64, device=dev)
    words = np.array([n // 4 for _, n in spans], dtype=np.int32)
    width = int(min(int(words.max()), MAX_WIDTH))
    table = array(words, dtype=int32, device=dev)
    dims = (len(spans), width)

    def run() -> None:
        launch(_zero_words, dims, [ptrs, table, width], device=dev, record_tape=False)

    return run
