"""Lowerings of the ``kd`` dialect: thread index, array shape, load, store, atomics.

An array is its descriptor (``ctypes_``); the address of element ``(i, j, ...)`` is
``data + i * strides[0] + j * strides[1] + ...`` in bytes, computed in 64 bits so
arrays of any size work while the thread index stays 32-bit. A kernel's fast entry
(``variants``) sums the offsets of its array parameters in 32 bits instead and loads
the parameters it only reads through ``__ldg`` (``FuncEmitter.narrow``,
``read_only``). Indices are not bounds-checked in release builds (debug builds
insert ``kd.check_bounds``).

Atomics use CUDA's native ``atomic*`` functions where one exists for the type
(float add included) and a compare-and-swap loop on the value's bits otherwise:
float min/max (kdsl's NaN and signed-zero rule, see ``helpers.float_minmax``) and
every 8- and 16-bit type (on the aligned 32-bit word around it). Comparing bits,
not values, ends the loop even when memory holds a NaN.
"""

from __future__ import annotations

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda import helpers as H
from kdsl.backends.cuda.arith import is_f16, scalar_rule
from kdsl.backends.cuda.emitter import FuncEmitter, Source
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Operation, Value
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

_FI = "__device__ __forceinline__"


def _tid(em: FuncEmitter, op: Operation) -> str:
    if not em.is_kernel:
        raise KdslCapabilityError("tid() is only available inside a kernel on cuda", op.loc)
    if op.attrs["ndim"] == 1:
        return "(int)kd_i"
    return em.tid_parts[op.attrs["dim"]]


def _array_shape(em: FuncEmitter, op: Operation) -> str:
    return f"(int){em.get(op.operands[0])}.shape[{op.attrs['dim']}]"


def element_ptr(em: FuncEmitter, arr: Value, idx: list[Value]) -> str:
    """C expression of the (``char *``) address of an element; no bounds check."""
    at: T.ArrayType = arr.type
    fn = H.element_ptr(em.src, at.ndim, arr in em.narrow)
    return f"{fn}({em.get(arr)}, {', '.join(em.get(i) for i in idx)})"


def _load(em: FuncEmitter, op: Operation) -> str:
    t = op.results[0].type
    p = element_ptr(em, op.operands[0], list(op.operands[1:]))
    if op.operands[0] in em.read_only:
        return f"{H.read_only_load(em.src, t)}({p})"
    if t == T.BOOL:  # bools are bytes in memory (NumPy's layout)
        return f"*(const unsigned char *){p} != 0"
    return f"*(const {em.ctype(t)} *){p}"


def _array_view(em: FuncEmitter, op: Operation) -> str:
    """``a[i...]`` as a descriptor of the remaining dims (``kd_view<N>_<K>``)."""
    at: T.ArrayType = op.operands[0].type
    k = len(op.operands) - 1
    rest = at.ndim - k
    name = f"kd_view{at.ndim}_{k}"
    src = em.src
    arr, out = src.ctype(at), src.ctype(op.results[0].type)
    at_fn = H.element_ptr(src, at.ndim)
    params = ", ".join(f"long long i{j}" for j in range(k))
    zeros = ", 0" * rest
    shape = ", ".join(f"a.shape[{k + d}]" for d in range(rest))
    strides = ", ".join(f"a.strides[{k + d}]" for d in range(rest))
    src.need(
        name,
        lambda: (
            f"{_FI} {out} {name}(const {arr} &a, {params}) {{ return {out}{{"
            f"{at_fn}(a, {', '.join(f'i{j}' for j in range(k))}{zeros}), {{{shape}}}, "
            f"{{{strides}}}}}; }}"
        ),
    )
    return f"{name}({em.get(op.operands[0])}, {', '.join(em.get(i) for i in op.operands[1:])})"


def _record(em: FuncEmitter, op: Operation) -> str:
    """The object record at address ``id``: the C struct has the record's layout
    (``kdsl.ir.records``; CUDA array descriptors also count strides in bytes)."""
    t = op.results[0].type
    return f"(*(const {em.ctype(t)} *){em.get(op.operands[0])})"


def _store(em: FuncEmitter, op: Operation) -> None:
    t = op.operands[0].type
    v = em.get(op.operands[0])
    p = element_ptr(em, op.operands[1], list(op.operands[2:]))
    if t == T.BOOL:
        em.line(f"*(unsigned char *){p} = (unsigned char){v};")
    else:
        em.line(f"*({em.ctype(t)} *){p} = {v};")


# -- atomics -----------------------------------------------------------------------

#: (kind, C type) -> a native CUDA call on (pointer, value); the pointer is cast as shown.
_NATIVE = {
    **{("add", c): "atomicAdd(p, v)" for c in ("int", "unsigned int", "float", "double",
                                               "unsigned long long")},
    ("add", "long long"): "(long long)atomicAdd((unsigned long long *)p, (unsigned long long)v)",
    ("sub", "int"): "atomicSub(p, v)", ("sub", "unsigned int"): "atomicSub(p, v)",
    ("sub", "float"): "atomicAdd(p, -v)", ("sub", "double"): "atomicAdd(p, -v)",
    ("sub", "unsigned long long"): "atomicAdd(p, 0ull - v)",
    ("sub", "long long"): "(long long)atomicAdd((unsigned long long *)p, 0ull - "
                          "(unsigned long long)v)",
    **{(k, c): f"atomic{k.capitalize()}(p, v)" for k in ("min", "max")
       for c in ("int", "unsigned int", "long long", "unsigned long long")},
    **{(k, c): f"atomic{k.capitalize()}(p, v)" for k in ("and", "or", "xor")
       for c in ("int", "unsigned int", "unsigned long long")},
    **{(k, "long long"): f"(long long)atomic{k.capitalize()}((unsigned long long *)p, "
                         "(unsigned long long)v)" for k in ("and", "or", "xor")},
    **{("exch", c): "atomicExch(p, v)" for c in ("int", "unsigned int", "float",
                                                 "unsigned long long")},
    ("exch", "long long"): "(long long)atomicExch((unsigned long long *)p, (unsigned long long)v)",
    ("exch", "double"): "__longlong_as_double((long long)atomicExch((unsigned long long *)p, "
                        "(unsigned long long)__double_as_longlong(v)))",
}  # fmt: skip


def _combine(src: Source, kind: str, et: T.ScalarType, cur: str, v: str) -> str:
    if kind == "exch":
        return v
    return scalar_rule(kind, et)(src, et, cur, v)


def _bits(et: T.ScalarType) -> tuple[str, str]:
    """(to bits, from bits) C format strings for a 32- or 64-bit scalar."""
    if et.is_float:
        if et.bits == 32:
            return "__float_as_uint({})", "__uint_as_float({})"
        return "(unsigned long long)__double_as_longlong({})", "__longlong_as_double((long long){})"
    u = CT.unsigned_c(et)
    return f"({u}){{}}", f"({CT.scalar_c(et)}){{}}"


def _small_bits(et: T.ScalarType) -> tuple[str, str]:
    """(to bits, from bits) for an 8- or 16-bit scalar held in the low bits of a word."""
    if is_f16(et):
        return "(unsigned int){}.bits", "kd_f16{{(unsigned short){}}}"
    if et.is_bool:
        return "(unsigned int){}", "({} != 0u)"
    mask = (1 << et.bits) - 1
    return f"((unsigned int){{}} & {mask:#x}u)", f"({CT.scalar_c(et)}){{}}"


def _word_around(et: T.ScalarType) -> str:
    """C lines declaring the aligned 32-bit word ``w`` around an 8- or 16-bit ``*p``, and
    where in it ``*p`` lies (``shift``, ``mask``)."""
    mask = (1 << et.bits) - 1
    return (
        "  unsigned int *w = (unsigned int *)((unsigned long long)p & ~3ull);\n"
        "  unsigned int shift = ((unsigned int)(unsigned long long)p & 3u) * 8u;\n"
        f"  unsigned int mask = {mask:#x}u << shift;\n"
    )


def atomic_helper(src: Source, kind: str, et: T.ScalarType) -> str:
    """The name of ``kd_atomic_<kind>_<tag>(T *p, T v)``, which gives the old value."""
    c = src.ctype(et)
    name = f"kd_atomic_{kind}_{CT.tag(et)}"
    native = _NATIVE.get((kind, c))

    def make() -> str:
        head = f"{_FI} {c} {name}({c} *p, {c} v) {{\n"
        if native is not None:
            return head + f"  return {native};\n}}"
        new = _combine(src, kind, et, "cur", "v")
        if et.bits >= 32:
            u = CT.unsigned_c(et)
            to, frm = _bits(et)
            return head + (
                f"  {u} *w = ({u} *)p;\n  {u} old = *(volatile {u} *)w, seen;\n"
                f"  do {{\n    seen = old;\n    {c} cur = {frm.format('seen')};\n"
                f"    old = atomicCAS(w, seen, {to.format(f'({new})')});\n"
                f"  }} while (old != seen);\n  return {frm.format('old')};\n}}"
            )
        to, frm = _small_bits(et)
        head += _word_around(et)
        return head + (
            "  unsigned int old = *(volatile unsigned int *)w, seen;\n"
            f"  do {{\n    seen = old;\n    {c} cur = {frm.format('((seen & mask) >> shift)')};\n"
            f"    {c} nv = {new};\n"
            f"    old = atomicCAS(w, seen, (seen & ~mask) | ({to.format('nv')} << shift));\n"
            f"  }} while (old != seen);\n  return {frm.format('((old & mask) >> shift)')};\n}}"
        )

    src.need(f"fn:{name}", make, feature=f"atomic.{kind}")
    return name


def cas_helper(src: Source, et: T.ScalarType) -> str:
    """The name of ``kd_atomic_cas_<tag>(T *p, T compare, T v)``, which gives the old value.

    ``atomicCAS`` on the value's bits (floats compare by bits); 8- and 16-bit types
    loop on the aligned 32-bit word around them until the other bytes hold still.
    """
    c = src.ctype(et)
    name = f"kd_atomic_cas_{CT.tag(et)}"

    def make() -> str:
        head = f"{_FI} {c} {name}({c} *p, {c} cmp, {c} v) {{\n"
        if et.bits >= 32:
            u = CT.unsigned_c(et)
            to, frm = _bits(et)
            return head + (
                f"  {u} old = atomicCAS(({u} *)p, {to.format('cmp')}, {to.format('v')});\n"
                f"  return {frm.format('old')};\n}}"
            )
        to, frm = _small_bits(et)
        head += _word_around(et)
        return head + (
            f"  unsigned int want = {to.format('cmp')} << shift;\n"
            f"  unsigned int put = {to.format('v')} << shift;\n"
            "  unsigned int old = *(volatile unsigned int *)w, seen;\n"
            "  do {\n    seen = old;\n    if ((seen & mask) != want) break;\n"
            "    old = atomicCAS(w, seen, (seen & ~mask) | put);\n"
            "  } while (old != seen);\n"
            f"  return {frm.format('((old & mask) >> shift)')};\n}}"
        )

    src.need(f"fn:{name}", make, feature="atomic.cas")
    return name


def _may_be_local(em: FuncEmitter) -> bool:
    """Whether an atomic's address may be thread-local memory: the module makes local
    arrays (``kd.local_array``), and CUDA atomics on local memory are illegal."""
    return "local_arrays" in em.src.features.names


def _local_or_atomic(em: FuncEmitter, et: T.ScalarType, p: str, atomic: str, update) -> str:
    """The old value at ``p`` after ``atomic`` (an expression giving it), or, where ``p``
    is thread-local memory (``__isLocal``), after a plain read-modify-write (no other
    thread sees that memory): ``update(old)`` emits the plain write."""
    old = em.declare(et)
    em.open(f"if (__isLocal({p})) {{")
    em.line(f"{old} = *{p};")
    update(old)
    em.close()
    em.open("else {")
    em.line(f"{old} = {atomic};")
    em.close()
    return old


def _lanes(em: FuncEmitter, t: T.Type, p: str, values: list[str]) -> list[tuple[str, list[str]]]:
    """(address, operand lanes) of each scalar lane of an atomic on a ``t`` at ``p``."""
    ec = em.ctype(T.elem_type(t))
    base = em.fresh()
    em.line(f"{ec} *{base} = ({ec} *){p};")
    if isinstance(t, T.ScalarType):
        return [(base, values)]
    return [(f"({base} + {j})", [f"{v}.c[{j}]" for v in values]) for j in range(CT.count(t))]


def _gather(em: FuncEmitter, t: T.Type, olds: list[str]) -> str:
    if isinstance(t, T.ScalarType):
        return olds[0]
    r = em.declare(t)
    for j, old in enumerate(olds):
        em.line(f"{r}.c[{j}] = {old};")
    return r


def _same_bits(et: T.ScalarType, a: str, b: str) -> str:
    if et.is_float:
        if et.bits not in (32, 64):
            raise KdslCapabilityError(f"atomic_cas of {et} on a thread-local array on cuda")
        to_bits, _ = _bits(et)
        return f"{to_bits.format(a)} == {to_bits.format(b)}"
    return f"{a} == {b}"


def _atomic_cas(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[1].type
    et = T.elem_type(t)
    p = element_ptr(em, op.operands[2], list(op.operands[3:]))
    cmp, v = em.get(op.operands[0]), em.get(op.operands[1])
    fn = cas_helper(em.src, et)
    ec = em.ctype(et)
    if isinstance(t, T.ScalarType) and not _may_be_local(em):
        return f"{fn}(({ec} *){p}, {cmp}, {v})"
    olds = []
    for pj, (cj, vj) in _lanes(em, t, p, [cmp, v]):
        atomic = f"{fn}({pj}, {cj}, {vj})"
        if _may_be_local(em):

            def update(old, pj=pj, cj=cj, vj=vj):
                em.line(f"if ({_same_bits(et, old, cj)}) *{pj} = {vj};")

            olds.append(_local_or_atomic(em, et, pj, atomic, update))
        else:
            olds.append(atomic)
    return _gather(em, t, olds)


def _atomic(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[0].type
    et = T.elem_type(t)
    kind = op.attrs["kind"]
    p = element_ptr(em, op.operands[1], list(op.operands[2:]))
    v = em.get(op.operands[0])
    fn = atomic_helper(em.src, kind, et)
    ec = em.ctype(et)
    if isinstance(t, T.ScalarType) and not _may_be_local(em):
        return f"{fn}(({ec} *){p}, {v})"
    olds = []
    for pj, (vj,) in _lanes(em, t, p, [v]):
        atomic = f"{fn}({pj}, {vj})"
        if _may_be_local(em):

            def update(old, pj=pj, vj=vj):
                em.line(f"*{pj} = {_combine(em.src, kind, et, old, vj)};")

            olds.append(_local_or_atomic(em, et, pj, atomic, update))
        else:
            olds.append(atomic)
    return _gather(em, t, olds)


CUDA.register("kd.tid", _tid)
CUDA.register("kd.block_dim", lambda em, op: "(int)blockDim.x")
CUDA.register("kd.fence", lambda em, op: em.line("__threadfence();", op.loc))
CUDA.register("kd.array_shape", _array_shape)
CUDA.register("kd.load", _load)
CUDA.register("kd.array_view", _array_view)
CUDA.register("kd.record", _record)
CUDA.register("kd.null_array", lambda em, op: f"{em.ctype(op.results[0].type)}{{}}")
CUDA.register("kd.store", _store)
CUDA.register("kd.atomic_rmw", _atomic)
CUDA.register("kd.atomic_cas", _atomic_cas)
