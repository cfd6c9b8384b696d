"""Loop versioning on dense arrays of vectors, so LLVM can vectorize their loops.

An array's strides are runtime values (counted in scalars, see ``types``). For a
loop over ``pos[j]`` LLVM's loop vectorizer only speculates a symbolic stride to
be 1, but the elements of a ``vec3`` array lie 3 scalars apart, so its guess
always fails and the scalar loop runs. The launch may pass any stride that is a
multiple of the scalar size (a view of every other element, a field of a wider
record), so the backend cannot assume density either.

So an innermost loop that reads or writes arrays of vectors or matrices, defined
outside it, is emitted twice: a copy in which each such array's innermost stride
is the constant ``count(dtype)`` (what a dense array has) and the general copy,
chosen by one runtime test before the loop. With a constant stride LLVM sees
interleaved accesses (``x, y, z`` of consecutive elements) and vectorizes them
with wide loads and shuffles. Only innermost loops are versioned, so nesting never
multiplies the copies.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import leaf_types, leaves, rebuild_all
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation, Value

_LOOPS = ("scf.for", "scf.while")
_MEMORY = {"kd.load": 0, "kd.store": 1, "kd.atomic_rmw": 1, "kd.atomic_cas": 2}  # array operand


def arrays_to_version(loop: Operation) -> list[Value]:
    """The arrays of vectors or matrices that innermost ``loop`` accesses, defined outside.

    Empty when ``loop`` holds another loop (only innermost loops are versioned).
    """
    inner = list(loop.walk())[1:]
    if any(op.name in _LOOPS for op in inner):
        return []
    defined = {r for op in inner for r in op.results}
    for op in (loop, *inner):
        defined.update(a for region in op.regions for b in region.blocks for a in b.args)
    used = [op.operands[_MEMORY[op.name]] for op in inner if op.name in _MEMORY]
    return vector_arrays(v for v in used if v not in defined)


def vector_arrays(values: Iterable[Value]) -> list[Value]:
    """The distinct arrays of vectors or matrices among ``values`` (e.g. kernel params).

    A thread loop can be versioned on them the same way: ``versioned(em, arrays, emit, [])``.
    """
    out: list[Value] = []
    for v in values:
        t = v.type
        dense = isinstance(t, T.ArrayType) and isinstance(t.dtype, T.VectorType | T.MatrixType)
        if dense and v not in out:
            out.append(v)
    return out


def _stride_slot(arr: Value) -> list[int]:
    return [2, arr.type.ndim - 1]


def versioned(
    em: Emitter, arrays: Sequence[Value], emit: Callable[[], list[Any]], types: Sequence[T.Type]
) -> list[Any]:
    """``emit()`` twice, for dense ``arrays`` (constant strides) and in general.

    ``emit`` lowers the loop at the builder's position and returns its results (of IR
    ``types``); the two copies' results meet in phis.
    """
    B = em.b
    saved = {a: em.get(a) for a in arrays}
    ok = None
    for a in arrays:
        stride = B.extract_value(saved[a], _stride_slot(a))
        dense = B.icmp_unsigned("==", stride, ir.Constant(LT.I64, LT.count(a.type.dtype)))
        ok = dense if ok is None else B.and_(ok, dense)
    fast, slow, merge = (em.new_block(n) for n in ("dense.loop", "strided.loop", "loop.end"))
    B.cbranch(ok, fast, slow)
    incoming = []
    B.position_at_end(fast)
    for a in arrays:
        n = ir.Constant(LT.I64, LT.count(a.type.dtype))
        em.values[a] = B.insert_value(saved[a], n, _stride_slot(a))
    incoming.append(([x for v in emit() for x in leaves(v)], B.block))
    B.branch(merge)
    em.values.update(saved)
    B.position_at_end(slow)
    incoming.append(([x for v in emit() for x in leaves(v)], B.block))
    B.branch(merge)
    B.position_at_end(merge)
    phis = [B.phi(lt, name="loop.val") for t in types for lt in leaf_types(t)]
    for vals, bb in incoming:
        for phi, v in zip(phis, vals):
            phi.add_incoming(v, bb)
    return rebuild_all(types, phis)
