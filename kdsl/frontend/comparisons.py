"""The common type two scalars of different types are compared in (``d < radius``).

Warp emits a comparison as C's ``a < b``, so C's usual arithmetic conversions let it
compare a ``float32`` with an ``int32`` (the int becomes a float). kdsl follows it
where that is sound: arithmetic still needs equal types (``i32 + f32`` is an error),
but a comparison gives a bool, so converting one operand cannot leak a surprising type
into later code. The rule:

- integer and float: the integer converts to the float type (C's rule, so results
  match Warp bit for bit, rounding of large integers included);
- two floats: the narrower converts to the wider;
- two integers: compared by value. Same signedness: the narrower widens. Mixed
  signedness: both widen to ``int64``, which holds every value of both, so ``-1 <
  1u`` is true (C's conversion to unsigned would make it false). ``uint64`` against
  a signed integer has no such common type and is a ``KdslTypeError`` asking for a
  cast;
- ``bool`` against a number is an error, as in kdsl's arithmetic.
"""

from __future__ import annotations

from kdsl.ir.types import I64, ScalarType, Type


def comparison_type(a: Type, b: Type) -> ScalarType | str:
    """The type both operands convert to, or why two scalar types do not compare.

    Only called for two different scalar types.
    """
    assert isinstance(a, ScalarType) and isinstance(b, ScalarType) and a != b
    if a.is_bool or b.is_bool:
        return (
            f"cannot compare {a} and {b}: convert the number with bool(x) or the bool with int(b)"
        )
    if a.is_float != b.is_float:
        return a if a.is_float else b
    if a.is_float or a.is_signed == b.is_signed:
        return a if a.bits >= b.bits else b
    unsigned = a if not a.is_signed else b
    if unsigned.bits < 64:
        return I64
    return (
        f"cannot compare {a} and {b}: no integer type holds every value of both; "
        f"cast one side (for example uint64(x) after checking x >= 0)"
    )
