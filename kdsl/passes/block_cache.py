"""Mark all-pairs loops whose loads a thread block can share (``block_cache``).

An all-pairs kernel (n-body, SPH densities, pairwise potentials) has every thread
run the same loop ``for j in range(n)`` over the same read-only arrays: each
thread loads ``a[j]`` for every ``j``. On a GPU, a block can load each element
once into block-local (shared) memory and let all its threads read it from there.
This pass recognises such loops and marks them with ``block_cache = T`` (the tile
length); the cuda backend lowers a marked loop to a tiled one (tiles of ``T``
elements loaded cooperatively between two barriers, then the original body over
the tile, in order). Backends that do not act on the mark run the loop as it is.

The mark changes no arithmetic: every thread still runs the body once per ``j``,
in increasing order, on the same values (the tile holds exactly ``a[j]``), so
results are bit-identical to the untiled loop.

A loop is marked when all of the following hold (``cached_loads`` checks them,
and the backend checks them again when it lowers the loop):

- it is an ``scf.for`` directly in a kernel's body (not nested in an ``scf.if``,
  ``scf.while`` or another loop, so every thread of a block reaches it and the
  barriers of the tiled form are met by all of them), with step 1;
- its bounds are uniform: computed from kernel parameters, constants and array
  shapes only, never from ``tid()`` or a load;
- its body (directly, not under a condition) loads ``a[j]`` from a 1-d array
  parameter ``a`` indexed by the loop variable itself, and ``a`` is only ever
  loaded from or measured in the kernel (no store, atomic, view or call reaches
  it), with an element type of plain scalars (not bool or float16), a vector or
  a matrix;
- nothing before the loop, nor the loop itself, may write memory: an alias of
  ``a`` written by the same thread before it reads the tile would otherwise be
  missed (writes after the loop, such as ``acc[i] = ...``, are fine);
- its tiles fit in what ``max_bytes`` leaves after the tiles of the kernel's
  loops marked before it (arrays that do not fit stay global loads).

Options: ``tile=256`` (elements per tile), ``max_bytes=16384`` (shared memory per
kernel, a third of the 48 KiB a block may declare statically). Running it twice
changes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation
from kdsl.ir import types as T
from kdsl.ir.core import BlockArgument, OpResult, Value
from kdsl.ir.ops_mem import ARRAY_SHAPE, LOAD
from kdsl.ir.ops_scf import BLOCK_CACHE_ATTR, FOR
from kdsl.ir.rewrite import constant_of, may_write
from kdsl.passes.manager import ModulePass

#: The attribute that marks a loop; its value is the tile length in elements.
ATTR = BLOCK_CACHE_ATTR
#: The default budget of shared memory for the tiles of one kernel, in bytes.
MAX_BYTES = 16384

#: Ops that give the same value in every thread when their operands do.
_UNIFORM_PREFIXES = ("arith.", "math.")
_UNIFORM_OPS = frozenset({"kd.array_shape", "kd.block_dim", "vec.construct", "vec.extract"})


def element_bytes(t: T.Type) -> int | None:
    """Bytes of one element of type ``t`` in a tile, or None if ``t`` is not tiled."""
    if isinstance(t, T.ScalarType):
        if t.is_bool or (t.is_float and t.bits == 16):
            return None
        return t.bits // 8
    if isinstance(t, T.VectorType):
        scalar = element_bytes(t.elem)
        return None if scalar is None else scalar * t.length
    if isinstance(t, T.MatrixType):
        scalar = element_bytes(t.elem)
        return None if scalar is None else scalar * t.rows * t.cols
    return None


def _is_uniform(v: Value, params: set[Value]) -> bool:
    if isinstance(v, BlockArgument):
        return v in params
    assert isinstance(v, OpResult)
    op = v.op
    if op.regions:
        return False
    if op.name == "arith.constant":
        return True
    if not (op.name.startswith(_UNIFORM_PREFIXES) or op.name in _UNIFORM_OPS):
        return False
    return all(_is_uniform(o, params) for o in op.operands)


def _read_only(arr: Value) -> bool:
    return all(u.opdef is LOAD or u.opdef is ARRAY_SHAPE for u, _ in arr.uses)


def cached_loads(func: Operation, loop: Operation, max_bytes: int, tile: int) -> list[Operation]:
    """The loads of ``loop`` (in ``func``) that a block may share, in body order.

    Empty when the loop does not qualify (see the module docstring); one load per
    array (the first), since a second load of ``a[j]`` in the body reads the same
    tile element. The tiles of the loops marked before ``loop`` in ``func`` count
    against ``max_bytes`` (all of a kernel's tiles are allocated at once).
    """
    body = func.regions[0].block
    if func.attrs.get("kind") != "kernel" or loop.opdef is not FOR or loop.parent is not body:
        return []
    is_const, step = constant_of(loop.operands[2])
    if not is_const or step != 1:
        return []
    params = set(body.args)
    if not all(_is_uniform(v, params) for v in loop.operands[:2]):
        return []
    ops = body.ops
    before = ops[: ops.index(loop)]
    if any(may_write(op) for op in [*before, loop]):
        return []
    used = sum(_tile_bytes(func, op, max_bytes) for op in before if op.opdef is FOR)
    inner = loop.regions[0].block
    iv = inner.args[0]
    found: dict[Value, Operation] = {}
    for op in inner.ops:
        if op.opdef is not LOAD or len(op.operands) != 2 or op.operands[1] is not iv:
            continue
        arr = op.operands[0]
        if arr in found or arr not in params or arr.type.ndim != 1 or not _read_only(arr):
            continue
        size = element_bytes(arr.type.dtype)
        if size is None or used + size * tile > max_bytes:
            continue
        used += size * tile
        found[arr] = op
    return list(found.values())


def _tile_bytes(func: Operation, loop: Operation, max_bytes: int) -> int:
    """Shared memory the tiles of the marked ``loop`` take (0 if it is not marked)."""
    tile = loop.attrs.get(ATTR)
    if not isinstance(tile, int) or tile < 1:
        return 0
    loads = cached_loads(func, loop, max_bytes, tile)
    return sum(tile * (element_bytes(ld.results[0].type) or 0) for ld in loads)


@dataclass(frozen=True)
class BlockCachePass(ModulePass):
    """Mark loops whose loads a block can share (see the module docstring)."""

    name: ClassVar[str] = "block-cache"
    tile: int = 256
    max_bytes: int = MAX_BYTES

    def __post_init__(self) -> None:
        if self.tile < 1 or self.max_bytes < 1:
            raise ValueError(
                f"block-cache: tile and max_bytes must be positive, got {self.tile}, {self.max_bytes}"
            )

    def apply(self, module: Module) -> bool:
        changed = False
        for func in module.funcs:
            if func.attrs.get("kind") != "kernel":
                continue
            for op in list(func.regions[0].block.ops):
                if op.opdef is not FOR or op.attrs.get(ATTR) == self.tile:
                    continue
                if cached_loads(func, op, self.max_bytes, self.tile):
                    op.attrs[ATTR] = self.tile
                    changed = True
        return changed
