"""Lowering of ``kd.local_array`` (a thread-local array) to a C local array.

The storage, ``T vN_s[n]`` of the element's C type, is declared at the top of the
function body, so a descriptor that leaves the block it was made in (a loop body, a
branch) never points at a dead array; NVCC keeps a small array indexed by constants
in registers. Each run of the op zero-fills it (a loop of ``= {}``, which needs no
header) where the op is (not with ``fill = "none"``, ``kdsl.ext.empty``: the contents
are undefined until written, as a plain C array's) and builds the descriptor (``struct kd_array<N>``, strides in bytes) over it, so the
memory ops work on it unchanged.
"""

from __future__ import annotations

import math

from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_local import dense_strides, fill_of

CUDA = LOWERINGS.for_backend("cuda")


def _local_array(em: FuncEmitter, op: Operation) -> str:
    t: T.ArrayType = op.results[0].type
    shape = tuple(op.attrs["shape"])
    elem = "unsigned char" if t.dtype == T.BOOL else em.ctype(t.dtype)  # bools are bytes
    storage = f"{em.fresh()}_s"
    # The top of the body: outside every loop and branch of the function.
    n = math.prod(shape)
    em.lines.insert(0, (1, f"{elem} {storage}[{n}];", op.loc))
    if fill_of(op) == "zero":
        k = em.fresh()
        em.line(f"for (int {k} = 0; {k} < {n}; ++{k}) {storage}[{k}] = {{}};")
    dims = ", ".join(str(n) for n in shape)
    strides = ", ".join(str(s) for s in dense_strides(t, shape, 1))
    return f"{em.ctype(t)}{{(char *){storage}, {{{dims}}}, {{{strides}}}}}"


CUDA.register("kd.local_array", _local_array)
