"""bfloat16 in kernels: a storage type whose elements load as float32 and store rounded.

An array of ``wp.bfloat16`` holds 16-bit patterns (``kdsl.ir.types.BF16``). Reading an
element gives the float32 with those bits in its upper half (exact); writing a float32
rounds it to nearest even, keeping NaN a NaN, as Warp, CUDA's ``__float2bfloat16_rn``
and the host's ``kdsl.ir.bfloat16.to_bits`` do. Both conversions are integer ops on the
bits, so every backend runs them unchanged. ``wp.bfloat16(x)`` in a kernel is ``x``
rounded to bfloat16, as a float32.

Atomics on bfloat16 arrays are refused (no backend has a 16-bit float atomic), and
bfloat16 parameters, struct fields and vector elements are too: store values in
bfloat16 arrays and compute in float32.
"""

from __future__ import annotations

import ast
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.ir import Value
from kdsl.ir.types import BF16, F32, U16, U32

#: Why a bfloat16 value cannot be used where it was (storage only).
STORAGE_ONLY = (
    "bfloat16 is a storage type in kdsl: use it as an array dtype (elements load as float32 "
    "and store rounded); pass and compute float32"
)


def load_value(em: Any, v: Value, node: ast.AST | None) -> Value:
    """The float32 a loaded bfloat16 ``v`` stands for (its bits, shifted up)."""
    bits = em.emit_typed("arith.bitcast", [v], U16, node)
    wide = em.emit_typed("arith.cast", [bits], U32, node)
    high = em.emit("arith.shl", wide, em.const(16, U32, node), node=node)
    return em.emit_typed("arith.bitcast", [high], F32, node)


def store_value(em: Any, x: Any, node: ast.AST | None) -> Value:
    """``x`` (a float32 value or a number) rounded to bfloat16, for a store."""
    f = em.value(x, node, want=F32)
    if f.type != F32:
        raise em.error(
            KdslTypeError,
            f"a bfloat16 array element takes a float32 value, not a {f.type}; convert it "
            "with float32(x)",
            node,
        )
    return em.emit_typed("arith.bitcast", [_rounded_bits(em, f, node)], BF16, node)


def round_value(em: Any, x: Any, node: ast.AST | None) -> Value:
    """``bfloat16(x)`` in a kernel: ``x`` rounded to bfloat16, as a float32."""
    f = em.value(x, node, want=F32)
    if f.type != F32:
        f = em.emit_typed("arith.cast", [f], F32, node)
    bits = em.emit_typed("arith.bitcast", [_rounded_bits(em, f, node)], BF16, node)
    return load_value(em, bits, node)


def _rounded_bits(em: Any, f: Value, node: ast.AST | None) -> Value:
    """The upper 16 bits of ``f`` rounded to nearest even (u16); NaN keeps a quiet bit."""

    def u32(n: int) -> Value:
        return em.const(n, U32, node)

    b = em.emit_typed("arith.bitcast", [f], U32, node)
    lsb = em.emit("arith.and", em.emit("arith.shr", b, u32(16), node=node), u32(1), node=node)
    rounded = em.emit("arith.add", em.emit("arith.add", b, u32(0x7FFF), node=node), lsb, node=node)
    is_nan = em.emit("arith.cmp", f, f, node=node, pred="ne")
    quiet = em.emit("arith.or", b, u32(0x0040_0000), node=node)
    chosen = em.emit("arith.select", is_nan, quiet, rounded, node=node)
    high = em.emit("arith.shr", chosen, u32(16), node=node)
    return em.emit_typed("arith.cast", [high], U16, node)
