"""A kernel's fast variant, and the launch-time test that picks it.

A release build emits each kernel twice in one unit (``lower``): the general entry,
exact for every launch (a linear grid of 256-thread blocks, 64-bit byte offsets,
plain loads), and, where it would differ, a fast entry (``fast_entry_name``) that

- takes an n-d thread index from an n-d CUDA grid (``blockIdx.x/y/z``) instead of
  dividing a linear index, when the kernel's only ``tid()`` is 2-d or 3-d and it
  uses nothing that assumes 1-d blocks (``block_dim()``);
- sums the byte offsets of its array parameters' elements in 32 bits (one
  ``int`` multiply-add per index, widened once), exact while every array parameter
  spans less than 2**31 bytes (``geometry.offsets_fit``);
- loads the array parameters it only reads (``kdsl.ir.array_access``) through the
  read-only data cache (``__ldg``), exact while no array it writes overlaps them
  (``geometry.disjoint``); only when every write of the kernel lands in an array parameter.

The values it computes are the general entry's, bit for bit: the same operations on
the same data, with addresses that agree for every in-bounds element. At launch,
``geometry.fast_geometry`` checks the arguments and the grid and gives the fast entry's grid
and block, or None for the general entry: an array of 2**31 bytes or more, a read
array overlapping a written one, or an n-d grid taller than CUDA's 65535 blocks in
y or z all fall back to it. Blocks are at most ``lower.BLOCK`` threads, the bound
that both entries' ``__launch_bounds__`` declare.
"""

from __future__ import annotations

from kdsl.ir import types as T
from kdsl.ir.array_access import array_param_access, writes_only_params
from kdsl.ir.core import Module
from kdsl.ir.ops_scf import BLOCK_CACHE_ATTR as TILE_ATTR

#: Ops that reach an array parameter's elements (the fast entry narrows their offsets).
_ACCESSES = frozenset({"kd.load", "kd.store", "kd.atomic_rmw", "kd.atomic_cas"})


class FastPlan:
    """What a kernel's fast entry does differently, by parameter position.

    ``grid_nd``: 2 or 3 for an n-d grid, 0 for the general entry's linear one;
    ``arrays``: (position, ndim, element bytes) of every array parameter, whose
    spans a launch checks; ``read_only``: positions loaded through ``__ldg``; ``written``: positions
    of the array parameters the kernel writes (checked against ``read_only``).
    ``checks``: (position, ndim, element bytes, role) per array, what a launch tests:
    role 1 for a read-only array, 2 for a written one, 0 for the others.

    A plain class, compared by value: a frozen dataclass costs a warm start (which
    imports this module to plan its first launch) about 0.7 ms to define.
    """

    __slots__ = ("arrays", "checks", "grid_nd", "read_only", "written")

    def __init__(
        self,
        grid_nd: int,
        arrays: tuple[tuple[int, int, int], ...],
        read_only: tuple[int, ...],
        written: tuple[int, ...],
    ) -> None:
        self.grid_nd = grid_nd
        self.arrays = arrays
        self.read_only = read_only
        self.written = written
        self.checks: tuple[tuple[int, int, int, int], ...] = tuple(
            (i, nd, item, 1 if i in read_only else 2 if i in written else 0)
            for i, nd, item in arrays
        )

    def _fields(self) -> tuple:
        return (self.grid_nd, self.arrays, self.read_only, self.written)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FastPlan) and self._fields() == other._fields()

    def __hash__(self) -> int:
        return hash(self._fields())

    def __repr__(self) -> str:
        return "FastPlan(grid_nd={!r}, arrays={!r}, read_only={!r}, written={!r})".format(
            *self._fields()
        )


def ldg_type(t: T.Type) -> bool:
    """True when loads of a ``t`` can go through ``__ldg`` (plain scalars, bool, and
    vectors or matrices of them; not float16 nor structs)."""
    if isinstance(t, T.VectorType | T.MatrixType):
        return ldg_type(t.elem)
    return isinstance(t, T.ScalarType) and t.c != "kd_f16"


def fast_plan(module: Module, symbol: str, debug: bool) -> FastPlan | None:
    """The fast entry of kernel ``symbol``, or None where it would be the general one
    (kernels that neither use an n-d ``tid()`` nor reach an array parameter's
    elements) or is not made: debug builds, whose checks need every access as
    written, and kernels with a ``block-cache`` tile, whose hot loop reads shared
    memory (a second entry would change little there and double NVRTC's time on
    their long bodies)."""
    if debug:
        return None
    func = module.get_func(symbol)
    if any(TILE_ATTR in op.attrs for op in func.walk()):
        return None
    params = func.regions[0].block.args
    ndims = {op.attrs["ndim"] for op in func.walk() if op.name == "kd.tid"}
    one_d_blocks = any(op.name == "kd.block_dim" for op in module.walk())
    grid_nd = 0
    if len(ndims) == 1 and min(ndims) in (2, 3) and not one_d_blocks:
        grid_nd = min(ndims)
    arrays = tuple(
        (i, p.type.ndim, T.storage_dtype(p.type.dtype).itemsize)
        for i, p in enumerate(params) if isinstance(p.type, T.ArrayType)
    )  # fmt: skip
    accessed = {
        i for i, p in enumerate(params)
        if any(u.name in _ACCESSES and k == u.opdef.array_operand for u, k in p.uses)
    }  # fmt: skip
    if not grid_nd and not accessed:
        return None
    access = array_param_access(module, symbol)
    read_only: tuple[int, ...] = ()
    if writes_only_params(module, symbol):
        read_only = tuple(
            i for i in sorted(accessed)
            if access[i].read and not access[i].write and ldg_type(params[i].type.dtype)
        )  # fmt: skip
    written = tuple(i for i, _, _ in arrays if access[i].write)
    return FastPlan(grid_nd, arrays, read_only, written)
