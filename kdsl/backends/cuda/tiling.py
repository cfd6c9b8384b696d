"""A loop the ``block-cache`` pass marked, lowered through shared memory.

The marked ``scf.for`` (step 1, uniform bounds, at the top of a kernel's body; see
``kdsl.passes.block_cache``) becomes a loop over tiles of ``T`` elements::

    __shared__ E s[T];                                  // one per cached array
    const unsigned int live = min(blockDim.x, kd_g.n - blockIdx.x * blockDim.x);
    for (long long t = lb; t < ub; t += T) {
      const int len = (int)min((long long)T, ub - t);
      __syncthreads();                                  // the last tile is read
      for (int k = threadIdx.x; k < len; k += live) s[k] = a[t + k];
      __syncthreads();                                  // this tile is loaded
      for (int kk = 0; kk < len; ++kk) { j = t + kk; body, reading s[kk] for a[j] }
    }

Threads past the launch's extent have returned at the kernel's start (``lower``).
They are the tail of the last block, so the live threads are the block's first
``live`` and share the loading between them; a returned thread no longer counts at
a barrier (PTX ISA, ``exit``: barriers it holds up are released). Every live thread
reaches the loop (it is not under a condition) with the same bounds, so all of them
meet the same barriers. The body runs for the same ``j`` in the same order on the
same values as the plain loop: results are bit-identical.

Debug builds lower the plain loop: their bounds checks must see each access.
"""

from __future__ import annotations

from kdsl.backends.base import split_block
from kdsl.backends.cuda import helpers as H
from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir.core import Operation, Value
from kdsl.ir.ops_mem import LOAD
from kdsl.passes.block_cache import ATTR, MAX_BYTES, cached_loads


def tiled_loads(em: FuncEmitter, op: Operation) -> list[Operation]:
    """The loads of ``op`` to serve from shared memory; empty to lower a plain loop."""
    tile = op.attrs.get(ATTR)
    if not isinstance(tile, int) or tile < 1 or not em.is_kernel or em.src.debug:
        return []
    return cached_loads(em.func, op, MAX_BYTES, tile)


def lower_tiled_for(em: FuncEmitter, op: Operation, loads: list[Operation]) -> list[str]:
    """Lower the marked loop ``op`` with ``loads`` (``tiled_loads``) through shared memory."""
    tile: int = op.attrs[ATTR]
    lb, ub, _, *init = em.args(op)
    types = [r.type for r in op.results]
    carried = [em.declare(t, v) for t, v in zip(types, init)]
    bufs: dict[Value, str] = {}
    for ld in loads:
        arr = ld.operands[0]
        bufs[arr] = em.fresh()
        em.line(f"__shared__ {em.ctype(ld.results[0].type)} {bufs[arr]}[{tile}];")
    live, t, n, k, kk = (em.fresh() for _ in range(5))
    em.line(f"const unsigned int {live} = min(blockDim.x, kd_g.n - blockIdx.x * blockDim.x);")
    em.open(f"for (long long {t} = {lb}; {t} < (long long){ub}; {t} += {tile}) {{")
    em.line(f"const int {n} = (int)min((long long){tile}, (long long){ub} - {t});")
    em.line("__syncthreads();")
    em.open(f"for (int {k} = (int)threadIdx.x; {k} < {n}; {k} += (int){live}) {{")
    for arr, buf in bufs.items():
        at = f"{H.element_ptr(em.src, 1)}({em.get(arr)}, {t} + {k})"
        em.line(f"{buf}[{k}] = *(const {em.ctype(arr.type.dtype)} *){at};")
    em.close()
    em.line("__syncthreads();")
    em.open(f"for (int {kk} = 0; {kk} < {n}; ++{kk}) {{")
    body = op.regions[0].block
    iv = body.args[0]
    ivc = em.ctype(iv.type)
    j = em.declare(iv.type, f"({ivc})({t} + {kk})")
    for a, name in zip(body.args, [j, *carried]):
        em.bind(a, name)
    ops, yielded = split_block(body)
    for inner in ops:
        arr = inner.operands[0] if inner.opdef is LOAD and len(inner.operands) == 2 else None
        if arr in bufs and inner.operands[1] is iv:
            saved, em.loc = em.loc, inner.loc
            em.bind(inner.results[0], em.declare(inner.results[0].type, f"{bufs[arr]}[{kk}]"))
            em.loc = saved
        else:
            em.lower_op(inner)
    em.assign(carried, [em.get(v) for v in yielded], types)
    em.close()
    em.close()
    return carried
