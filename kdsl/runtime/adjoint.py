"""Adjoint launches: compile a kernel's adjoint on first use, size its tapes, run it.

The adjoint function comes from the ``adjoint`` pass (``kdsl.passes.adjoint``). It
is built only when a backward pass first needs it, and cached per kernel like any
compiled kernel. Loops with a run-time trip count need tapes: when the pass also
made a counting function, it runs first (on the same arguments) and reports each
loop's most iterations, so the tapes are allocated exactly; their total is capped
by ``kdsl.config.max_tape_bytes``.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl import config
from kdsl.compiler import adjoint_module
from kdsl.errors import KdslError, KdslLaunchError, KdslRuntimeError
from kdsl.ir import Module
from kdsl.ir import types as T
from kdsl.ir.vjp import is_differentiable
from kdsl.passes.adjoint.analysis import has_grad_arrays
from kdsl.runtime.array import array
from kdsl.runtime.graphs import state as _graphs
from kdsl.runtime.graphs.state import run_or_record
from kdsl.runtime.launch import check_tid, launch_plan, normalize_dim, resolve_stream
from kdsl.runtime.modules import backward_enabled
from kdsl.runtime.stream import ScopedStream, current_stream

_ADJ_ATTR = "_kdsl_adjoint"
_COUNT_ATTR = "_kdsl_counter"


class DerivedKernel:
    """A kernel-like object for the launch machinery: a kernel's adjoint or tape counter.

    Its module derives from the kernel's source alone, so it is found in the kernel
    cache's source index like a kernel (``source_fingerprint``): a warm start restores
    what launches need (``build_facts``) instead of running the frontend, the adjoint
    pass and the pipelines.
    """

    def __init__(self, kernel: Any, suffix: str, what: str) -> None:
        self.base = kernel
        self.key = kernel.key + suffix
        self.name = f"{kernel.name} ({what})"
        self.module = getattr(kernel, "module", None)
        self.source_file = getattr(kernel, "source_file", None)
        self._facts: dict[str, Any] | None = None

    @property
    def options(self) -> dict[str, Any]:
        return self.base.options

    @property
    def tid_ndim(self) -> int:
        return self.base.tid_ndim

    @property
    def fn(self) -> Any:
        """The kernel's Python function (its source is this module's source)."""
        return self.base.fn

    def source_fingerprint(self, memo: Any = None) -> str | None:
        """The kernel's fingerprint (``Kernel.source_fingerprint``): the derived module
        is a function of it and of kdsl's code; the symbol (``key``) tells them apart."""
        fingerprint = getattr(self.base, "source_fingerprint", None)
        return None if fingerprint is None else fingerprint(memo)

    def build_module(self) -> Module:
        """The kernel's module, optimized, with only this derived function in it."""
        module = adjoint_module(self.base)
        for f in module.funcs:
            if f.attrs["sym_name"] != self.key:
                f.erase()
        if not module.has_func(self.key):
            raise KdslError(f"kernel '{self.base.name}' has no {self.name}")
        func = module.get_func(self.key)
        args = func.regions[0].block.args
        n = len(self.base.arg_types)
        self._facts = {
            "arg_names": [a.name_hint or f"arg{i}" for i, a in enumerate(args)],
            "arg_types": [a.type for a in args],
            # (name, type, whether the code uses it) of each parameter after the adjoints.
            "hidden": [(a.name_hint, a.type, bool(a.uses)) for a in args[2 * n :]],
            "tape_sites": func.attrs.get("tape_sites"),
            "tape_slots": func.attrs.get("tape_slots"),
            # The kernel was built too: its own facts (tid_ndim), where it keeps any.
            "base": getattr(self.base, "build_facts", dict)(),
        }
        return module

    def build_facts(self) -> dict[str, Any]:
        """What the last ``build_module`` learnt that launches need."""
        return dict(self._facts or {})

    def restore_build_facts(self, facts: dict[str, Any]) -> None:
        """Take ``build_facts`` of an earlier build of this same source (a cache hit)."""
        if self._facts is None and facts:
            self._facts = dict(facts)
            restore = getattr(self.base, "restore_build_facts", None)
            if restore is not None:  # an adjoint launched before its kernel
                restore(facts.get("base") or {})

    def _fact(self, name: str) -> Any:
        if self._facts is None:
            self.build_module()
        return self._facts[name]  # type: ignore[index]

    @property
    def arg_names(self) -> list[str]:
        return self._fact("arg_names")

    @property
    def arg_types(self) -> list[T.Type]:
        return self._fact("arg_types")

    @property
    def hidden(self) -> list[tuple[str, T.Type, bool]]:
        """(name, type, used) of each parameter after the adjoints (tapes, flags)."""
        return self._fact("hidden")

    @property
    def tape_sites(self) -> Any:
        """Where each tape is written (the adjoint pass's ``tape_sites``)."""
        return self._fact("tape_sites")

    @property
    def tape_slots(self) -> Any:
        """Each loop's tape length (the adjoint pass's ``tape_slots``; -1: at run time)."""
        return self._fact("tape_slots")


def adjoint_kernel(kernel: Any) -> DerivedKernel:
    """The (cached) adjoint of ``kernel``; raises when the kernel disabled its backward pass."""
    if not backward_enabled(kernel):
        raise KdslError(
            f"kernel '{kernel.name}' was compiled with enable_backward=False, so it has no "
            "backward pass; remove the option to differentiate it"
        )
    adj = getattr(kernel, _ADJ_ATTR, None)
    if adj is None:
        from kdsl.passes.adjoint import ADJ_SUFFIX

        adj = DerivedKernel(kernel, ADJ_SUFFIX, "adjoint")
        setattr(kernel, _ADJ_ATTR, adj)
    return adj


def _counter(kernel: Any) -> DerivedKernel:
    c = getattr(kernel, _COUNT_ATTR, None)
    if c is None:
        from kdsl.passes.adjoint import COUNT_SUFFIX

        c = DerivedKernel(kernel, COUNT_SUFFIX, "tape counter")
        setattr(kernel, _COUNT_ATTR, c)
    return c


def launch_adjoint(
    kernel: Any,
    dim: Any,
    args: Sequence[Any],
    adj_args: Sequence[Any],
    device: Any = None,
    stream: Any = None,
    backend: Any = None,
) -> None:
    """Run the adjoint of ``kernel`` over ``dim``.

    ``args`` are the forward launch's arguments in parameter order; ``adj_args`` one
    entry per parameter: the gradient array of an array parameter (input gradients
    receive ``+=``, output gradients hold the incoming gradient) or None when no
    gradient is wanted (scalars' entries are ignored).

    A backward pass launches many adjoints with the host waiting, so the per-launch
    work is kept small: what depends only on the kernel, device and backend is worked
    out once (``_AdjointPlan``), and a launch outside a graph capture goes through the
    plan's packed-launch reuse (``LaunchReuse``), as a forward launch does.
    """
    adj = adjoint_kernel(kernel)
    if type(dim) is int and dim >= 0:
        dims: tuple[int, ...] = (dim,)
    elif type(dim) is tuple and 0 < len(dim) < 5 and all(type(d) is int and d >= 0 for d in dim):
        dims = dim  # a tape replays its launches' normalized grids
    else:
        dims = normalize_dim(dim, kernel.name)
    check_tid(kernel, dims)
    plan = launch_plan(adj, device, backend)
    ap = _adjoint_plan(adj, plan)
    n = ap.n
    if len(args) != n or len(adj_args) != n:
        raise KdslLaunchError(
            f"kernel '{kernel.name}': its adjoint takes {n} arguments and {n} adjoints, got "
            f"{len(args)} and {len(adj_args)}"
        )
    dev = plan.device
    stream = resolve_stream(dev, stream)
    mask = _owned_mask(args, adj_args) if ap.owned_at is not None else 0
    known = None
    if ap.hidden is not None and not _graphs.ACTIVE and plan.reuse.tokens is not None:
        extra = ap.gradients_key(adj_args, mask)
        if extra is not None:
            known = plan.reuse.object_key(args, dims, stream, extra)
            if known is not None and plan.reuse.run_known(known):
                return  # these objects' adjoint ran before: nothing to convert or key
    convs = plan.converters
    primal = [conv(v) for conv, v in zip(convs, args)]
    adjoints = [ap.adjoint_arg(i, role, v, g, p, stream) for i, (role, v, g, p) in
                enumerate(zip(ap.roles, args, adj_args, primal))]  # fmt: skip
    if ap.hidden is not None:  # no tape is read: the hidden arguments are fixed
        hidden, status = list(ap.hidden), None
    else:
        hidden, status = _hidden_args(kernel, adj, dims, primal, dev, backend, stream)
    if ap.owned_at is not None:
        hidden[ap.owned_at] = mask
    converted = primal + adjoints + [convs[2 * n + i](h) for i, h in enumerate(hidden)]
    if _graphs.ACTIVE:
        run_or_record(plan, dims, converted, stream)
    else:
        plan.reuse.launch(dims, converted, stream, None, (known, [*args, *adj_args]))
    if status is not None and int(status.numpy()[0]) != 0:
        raise KdslRuntimeError(
            f"the backward pass of kernel '{kernel.name}' ran a dynamic loop more times than "
            "its counting pass measured (control flow that changes between runs, such as one "
            "that depends on atomics); its gradients are incomplete"
        )


# How ``_AdjointPlan.adjoint_arg`` makes a parameter's adjoint argument.
_GRAD_ARRAY, _SCRATCH_ARRAY, _STRUCT, _VALUE = range(4)


class _AdjointPlan:
    """What every adjoint launch of one kernel on one launch plan shares: each
    parameter's role, and the hidden arguments when they do not depend on the launch
    (no tape is read, so the counting pass and the tapes' sizes are not needed)."""

    __slots__ = ("convs", "dev", "hidden", "n", "owned_at", "plan", "roles", "scratch")

    def __init__(self, kernel: Any, adj: DerivedKernel, plan: Any) -> None:
        self.plan = plan
        self.dev = plan.device
        self.convs = plan.converters
        types = kernel.arg_types
        self.n = len(types)
        self.roles = [_role(t) for t in types]
        #: Per parameter index: scratch gradient arrays for arrays without one (cpu only).
        self.scratch: dict[tuple, Any] = {}
        self.owned_at = next((j for j, (name, _, _) in enumerate(adj.hidden)
                              if name == "grad_owned"), None)  # fmt: skip
        self.hidden: list | None = None
        if all(name == "grad_owned" or not live for name, _, live in adj.hidden):
            self.hidden = [_placeholder(name, t, self.dev) for name, t, _ in adj.hidden]

    def gradients_key(self, adj_args: Sequence[Any], mask: int) -> tuple | None:
        """The part of an object key (``LaunchReuse.object_key``) after the primal
        arguments: the gradient arrays by identity and the ownership mask; None when a
        launch with these gradients must be converted (an array without a gradient gets
        scratch memory, a struct its fields' gradients, a number an adjoint value)."""
        key: list[Any] = [mask]
        for role, g in zip(self.roles, adj_args):
            if role == _GRAD_ARRAY and type(g) is array:
                key.append(id(g))
            elif role != _VALUE or g is not None:
                return None
        return tuple(key)

    def adjoint_arg(
        self, i: int, role: int, v: Any, g: Any, converted: Any, stream: Any = None
    ) -> Any:
        """The converted adjoint argument of parameter ``i``: value ``v`` (``converted``
        as the primal argument), gradient ``g``, for a launch on ``stream``."""
        conv = self.convs[self.n + i]
        if role == _GRAD_ARRAY:
            return conv(self._scratch(i, v, stream) if g is None else g)
        if role == _SCRATCH_ARRAY:
            return conv(self._scratch(i, v, stream))
        if role == _STRUCT and g is None:
            return conv(_struct_adjoint(v, self.dev))
        # A scalar's adjoint is an unused input of the adjoint kernel (as in Warp).
        return converted if g is None else conv(g)

    def _scratch(self, i: int, v: Any, stream: Any = None) -> Any:
        """Zeros shaped like ``v`` for gradients nobody asked for (they land there).

        Outside a graph capture, on the cpu or for a launch on the device's current
        stream (where ``zero_`` clears it, so in order after the launch that used it
        last), the memory is kept per parameter (and calling thread) and cleared before
        each launch, so repeated launches pass the same buffer (and can reuse their
        packed arguments); elsewhere it is fresh.
        """
        from kdsl.runtime import alloc

        if not isinstance(v, array):
            return v
        if _graphs.ACTIVE or not (self.dev.is_cpu or stream is current_stream(self.dev)):
            if _graphs.ACTIVE or stream is None:
                return alloc.zeros_like(v, device=self.dev)
            # Zeroed (and taken from the pool) on the stream the adjoint runs on: zeroed
            # on the current one, nothing would order the fill before the kernel.
            with ScopedStream(stream, sync_enter=False):
                return alloc.zeros_like(v, device=self.dev)
        key = (i, threading.get_ident(), v.shape, v.dtype)
        z = self.scratch.get(key)
        if z is None:
            if len(self.scratch) >= _MAX_SCRATCH:
                self.scratch.clear()
            z = self.scratch[key] = alloc.zeros_like(v, device=self.dev)
        else:
            z.zero_()
        return z


#: Scratch gradient arrays kept per adjoint plan (cleared when full).
_MAX_SCRATCH = 16


def _placeholder(name: str, t: T.Type, dev: Any) -> Any:
    """A hidden argument the adjoint code never reads (an unread tape or status), or 0
    for ``grad_owned`` (filled at each launch)."""
    from kdsl.runtime import alloc
    from kdsl.types import class_of

    if name == "grad_owned":
        return 0
    if name == "tape_status":
        return alloc.empty(1, dtype=class_of(T.I32), device=dev)
    return alloc.empty((1, 1), dtype=class_of(t.dtype), device=dev)


def _role(t: T.Type) -> int:
    if isinstance(t, T.ArrayType):
        return _GRAD_ARRAY if is_differentiable(t.dtype) else _SCRATCH_ARRAY
    if isinstance(t, T.StructType) and has_grad_arrays(t):
        return _STRUCT
    return _VALUE


_PLANS_ATTR = "_kdsl_adjoint_plans"


def _adjoint_plan(adj: DerivedKernel, plan: Any) -> _AdjointPlan:
    """The cached ``_AdjointPlan`` of ``adj`` for launch plan ``plan`` (a new launch plan,
    after an option or debug setting changed, gets a new one)."""
    plans = getattr(adj, _PLANS_ATTR, None)
    if plans is None:
        plans = {}
        setattr(adj, _PLANS_ATTR, plans)
    ap = plans.get(id(plan))
    if ap is None or ap.plan is not plan:
        if len(plans) >= 8:
            plans.clear()
        ap = plans[id(plan)] = _AdjointPlan(adj.base, adj, plan)
    return ap


def _struct_adjoint(value: Any, dev: Any) -> Any:
    """The adjoint of a struct argument: its array fields' gradients (``.grad``, or
    scratch zeros for an array without one), its other fields as they are (as Warp)."""
    from kdsl.runtime import alloc

    out = type(value)()
    for name, ft in value.__kdsl_type__.fields:
        x = getattr(value, name)
        if isinstance(ft, T.ArrayType) and x is not None:
            g = getattr(x, "grad", None)
            x = g if g is not None else alloc.zeros_like(x, device=dev)
        elif isinstance(ft, T.StructType) and x is not None and has_grad_arrays(ft):
            x = _struct_adjoint(x, dev)
        setattr(out, name, x)
    return out


def _hidden_args(kernel, adj, dims, primal, dev, backend, stream) -> tuple[list, Any]:
    """The tape arrays (and status flag) of one adjoint launch.

    Tapes the adjoint reads are sized exactly (after the counting pass when a loop's
    trip count is dynamic); parameters the optimized code no longer uses get a
    one-element placeholder, and when no tape is read the counting pass is skipped.
    """
    from kdsl.runtime import alloc
    from kdsl.types import class_of

    if not adj.hidden:
        return [], None
    threads = int(np.prod(dims))
    used = [(name, t) for name, t, live in adj.hidden
            if live and name not in ("tape_status", "grad_owned")]  # fmt: skip
    slots = _tape_slots(kernel, adj, dims, primal, dev, backend, stream, used)
    _check_budget(kernel, used, slots, adj.tape_sites, threads)
    hidden: list[Any] = []
    status = None
    for name, t, live in adj.hidden:
        if name == "grad_owned":
            hidden.append(0)  # filled by the caller
        elif name == "tape_status":
            status = alloc.zeros(1, dtype=class_of(T.I32), device=dev) if live else None
            hidden.append(status if live else alloc.empty(1, dtype=class_of(T.I32), device=dev))
        elif not live:
            hidden.append(alloc.empty((1, 1), dtype=class_of(t.dtype), device=dev))
        else:
            hidden.append(_tape_array(t, threads, max(slots[_tape_index(name)], 1), dev))
    return hidden, status


def _owned_mask(args: Sequence[Any], adj_args: Sequence[Any]) -> int:
    """Bit i set when gradient i is parameter i's own ``.grad`` and the array does not
    ``retain_grad``: a store into it then consumes (zeroes) the gradient it read."""
    mask = 0
    for i, (a, g) in enumerate(zip(args[:63], adj_args)):
        if g is not None and getattr(a, "grad", None) is g and not a.retain_grad:
            mask |= 1 << i
    return mask


def _tape_array(t: T.ArrayType, threads: int, slots: int, dev: Any) -> Any:
    """A ``[thread, iteration]`` tape whose memory layout suits the device.

    On a GPU, consecutive threads should touch consecutive addresses (coalescing), so
    the memory is iteration-major and the kernel sees a transposed, strided view; a
    CPU thread walks its own row, so there it is thread-major.
    """
    from kdsl.runtime import alloc
    from kdsl.types import class_of

    if dev.is_cpu:
        return alloc.empty((threads, slots), dtype=class_of(t.dtype), device=dev)
    a = alloc.empty((slots, threads), dtype=class_of(t.dtype), device=dev)
    return array._wrap(a._buf.swapaxes(0, 1), a._t, a._device)


def _tape_slots(kernel, adj, dims, primal, dev, backend, stream, used) -> list[int]:
    """Each loop's tape length: static, measured by the counting pass, or 0 when unread."""
    from kdsl.runtime import alloc
    from kdsl.types import class_of

    slots = list(adj.tape_slots)
    read = {_tape_index(name) for name, _ in used}
    if all(s >= 0 or i not in read for i, s in enumerate(slots)):
        return [s if i in read else 0 for i, s in enumerate(slots)]
    counter = _counter(kernel)
    plan = launch_plan(counter, dev, backend)
    counts = alloc.zeros(len(slots), dtype=class_of(T.I32), device=dev)
    args = primal + [plan.converters[-1](counts)]
    run_or_record(plan, dims, args, stream)
    measured = counts.numpy()
    return [int(measured[i]) if s < 0 else s for i, s in enumerate(slots)]


def _itemsize(t: T.Type) -> int:
    return T.elem_type(t).np_dtype.itemsize * int(np.prod(T.value_shape(t), dtype=np.int64))


def _tape_index(name: str) -> int:
    """The loop index ``L`` of a tape parameter named ``tape<L>_<j>``."""
    return int(name[len("tape") :].split("_")[0])


def _check_budget(kernel, used, slots, sites, threads) -> None:
    need = [0] * len(slots)
    items = [0] * len(slots)
    for name, t in used:
        loop = _tape_index(name)
        items[loop] += _itemsize(t.dtype)
        need[loop] += threads * max(slots[loop], 1) * _itemsize(t.dtype)
    total = sum(need)
    if total > config.max_tape_bytes:
        worst = max(range(len(need)), key=need.__getitem__)
        raise KdslError(
            f"the backward pass of kernel '{kernel.name}' needs {total} bytes of loop tapes, "
            f"more than kdsl.config.max_tape_bytes = {config.max_tape_bytes}; the largest is "
            f"the loop at {sites[worst]}: {slots[worst]} iterations x {threads} threads x "
            f"{items[worst]} bytes. Raise the limit, launch fewer threads per backward pass, "
            "or shorten the loop"
        )
