"""What the adjoint needs to know about the kernel it differentiates.

``Primal`` wraps the forward kernel and answers the questions both sweeps ask:
which loops can contribute to a gradient, which arrays each thread owns, which
function a call reaches. ``check_differentiable`` refuses what has no adjoint
before anything is built. The region helpers (``defined_in``, ``outer_uses``) say
which values a structured op sees from outside.
"""

from __future__ import annotations

import warnings

from kdsl.errors import KdslError, KdslGradientWarning, render_loc
from kdsl.ir import Module, Operation, Value
from kdsl.ir.ops_local import is_local_array
from kdsl.ir.types import ArrayType, StructType, Type
from kdsl.ir.vjp import is_differentiable

#: Memory ops whose array operand's adjoint the sweeps read or write, with the
#: operand's position (the indices follow it).
ARRAY_ACCESSES = {"kd.load": 0, "kd.store": 1, "kd.atomic_rmw": 1}


class Primal:
    """The kernel being differentiated, and the facts about it the sweeps ask for."""

    def __init__(self, module: Module, kernel: Operation) -> None:
        self.module = module
        self.func = kernel
        self.sym: str = kernel.attrs["sym_name"]
        self.block = kernel.regions[0].block
        #: The kernel's parameters that get gradient arrays in the adjoint: differentiable
        #: arrays, and structs holding some (their adjoint struct holds the fields' grads).
        self.grad_arrays = {a for a in self.block.args if has_grad_arrays(a.type)}
        self._matters: dict[Operation, bool] = {}
        self._owned: dict[Value, bool] = {}

    def callee(self, call: Operation) -> Operation:
        """The function a ``func.call`` calls."""
        return self.module.get_func(call.attrs["callee"])

    def matters(self, op: Operation) -> bool:
        """Whether a loop can contribute to any gradient (else it is not reversed)."""
        hit = self._matters.get(op)
        if hit is None:
            hit = any(is_differentiable(r.type) for r in op.results) or any(
                inner.name in ARRAY_ACCESSES
                and base_array(inner.operands[ARRAY_ACCESSES[inner.name]]) in self.grad_arrays
                for inner in op.walk()
            )
            self._matters[op] = hit
        return hit

    def exclusive(self, arr: Value) -> bool:
        """Whether every access to ``arr`` indexes it by the thread index itself.

        Then each thread owns its elements, and so their gradients: the adjoint may
        accumulate without atomics. (Passing one array as two parameters breaks this,
        as it breaks the forward kernel's own assumptions.)
        """
        hit = self._owned.get(arr)
        if hit is None:
            nd = arr.type.ndim
            # A view (kd.array_view) reaches elements other threads may own: atomics.
            hit = arr in self.block.args
            for op, index in arr.uses if hit else ():
                if op.name == "kd.array_view":
                    hit = False
                    break
                at = ARRAY_ACCESSES.get(op.name)
                if at is None:
                    continue
                idx = op.operands[at + 1 : at + 1 + nd]
                if index != at or not all(is_tid(v, d, nd) for d, v in enumerate(idx)):
                    hit = False
                    break
            self._owned[arr] = hit
        return hit


def check_differentiable(primal: Primal) -> None:
    """Refuse calls and used atomic results the adjoint cannot replay; warn about a
    kernel that reads an array after writing it (the replay reads the new values).
    """
    written: set[Value] = set()
    for op in primal.func.walk():
        if op.name == "func.call" and not primal.callee(op).attrs.get("custom_grad"):
            raise KdslError(
                f"kdsl cannot differentiate a call to '{op.attrs['callee']}' that was not "
                "inlined (recursive functions have no adjoint)", op.loc, primal.sym)  # fmt: skip
        if (
            op.name in ("kd.atomic_rmw", "kd.atomic_cas")
            and op.results[0].uses
            and not _on_local_array(op)  # thread-local: the replay redoes it
        ):
            kind = op.attrs.get("kind", "cas")
            raise KdslError(
                f"the value returned by atomic_{kind} is used, and the backward "
                "pass cannot replay it; launch this kernel with enable_backward=False or "
                "stop using the returned value", op.loc, primal.sym)  # fmt: skip
        if op.name in ("kd.store", "kd.atomic_rmw"):
            written.add(op.operands[1])
        elif op.name == "kd.atomic_cas":
            written.add(op.operands[2])
        elif op.name == "kd.load" and op.operands[0] in written:
            arr = op.operands[0]
            if arr in primal.block.args and is_differentiable(arr.type.dtype):
                warnings.warn(
                    f"kernel reads array '{arr.name_hint}' after writing it; its gradient "
                    "replays the read with the written value and may be wrong\n"
                    + render_loc(op.loc, primal.sym), KdslGradientWarning, stacklevel=2)  # fmt: skip
                written.discard(arr)  # warn once per array


def _on_local_array(op: Operation) -> bool:
    return is_local_array(base_array(op.operands[op.opdef.array_operand]))


def has_grad_arrays(t: Type) -> bool:
    """Whether values of ``t`` hold differentiable arrays: ``t`` is one, or a struct with
    one among its fields (at any depth)."""
    if isinstance(t, ArrayType):
        return is_differentiable(t.dtype)
    return isinstance(t, StructType) and any(has_grad_arrays(ft) for _, ft in t.fields)


def base_array(arr: Value) -> Value:
    """Where an array comes from: the start of a ``kd.array_view`` chain, or the struct a
    chain of ``struct.extract`` reads it from (``arr`` itself when neither)."""
    op = getattr(arr, "op", None)
    while op is not None and op.name in ("kd.array_view", "struct.extract"):
        arr = op.operands[0]
        op = getattr(arr, "op", None)
    return arr


def is_tid(v: Value, dim: int, ndim: int) -> bool:
    """``v`` is component ``dim`` of an ``ndim``-d thread index (1-d: the linear index)."""
    op = getattr(v, "op", None)
    return (
        op is not None
        and op.name == "kd.tid"
        and op.attrs["dim"] == dim
        and op.attrs["ndim"] == ndim
    )


def defined_in(op: Operation) -> set[Value]:
    """The values defined inside ``op``'s regions (results and block arguments)."""
    out: set[Value] = set()
    for inner in op.walk():
        if inner is not op:
            out.update(inner.results)
        for r in inner.regions:
            out.update(r.block.args)
    return out


def outer_uses(op: Operation) -> list[Value]:
    """Differentiable values defined outside ``op`` that ops inside it use, in order."""
    inside = defined_in(op)
    seen: dict[Value, None] = {}
    for inner in op.walk():
        if inner is op:
            continue
        for v in inner.operands:
            if v not in inside and is_differentiable(v.type):
                seen.setdefault(v, None)
    return list(seen)
