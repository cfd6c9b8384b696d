"""Backend capabilities a module needs, and the check that the backend has them.

A backend advertises ``capabilities`` (``kdsl backends`` lists them). The compile
driver checks each kernel against them before emitting code, so a kernel that needs
one its backend lacks fails with a ``KdslCapabilityError`` naming the capability and
the first source line that needs it, instead of failing somewhere in code
generation. The conformance suite's capability test (``tests/conformance``) checks
the other direction: every advertised capability is exercised by a passing case.

The capability vocabulary: ``fp16``, ``fp32``, ``fp64`` (float values of that width,
array elements and struct fields included), ``int8``, ``int16``, ``int64`` (integers
of that width, signed or unsigned) and ``atomics`` (any atomic read-modify-write).
"""

from __future__ import annotations

from kdsl.errors import KdslCapabilityError
from kdsl.ir import Module, Operation
from kdsl.ir.types import ArrayType, MatrixType, ScalarType, StructType, Type, VectorType
from kdsl.passes.features import analyze_features

#: The capability each scalar type needs (types absent here need none: bool, i32, u32).
CAPABILITY_OF_SCALAR = {
    "f16": "fp16", "f32": "fp32", "f64": "fp64", "i8": "int8", "u8": "int8",
    "i16": "int16", "u16": "int16", "i64": "int64", "u64": "int64",
}  # fmt: skip

#: What each capability is, for error messages.
DESCRIPTION = {
    "fp16": "float16 values", "fp32": "float32 values", "fp64": "float64 values",
    "int8": "8-bit integers", "int16": "16-bit integers", "int64": "64-bit integers",
    "atomics": "atomic operations",
}  # fmt: skip

_ATOMIC_OPS = ("kd.atomic_rmw", "kd.atomic_cas")


def required_capabilities(module: Module) -> frozenset[str]:
    """The capabilities ``module`` needs (see the module docstring for the vocabulary)."""
    features = analyze_features(module)
    caps = {CAPABILITY_OF_SCALAR[s] for s in features.scalar_types if s in CAPABILITY_OF_SCALAR}
    if features.atomics:
        caps.add("atomics")
    return frozenset(caps)


def check_capabilities(backend_name: str, advertised: frozenset[str], module: Module) -> None:
    """Raise ``KdslCapabilityError`` when ``module`` needs a capability not ``advertised``."""
    missing = sorted(required_capabilities(module) - advertised)
    if not missing:
        return
    cap = missing[0]
    op = _first_needing(module, cap)
    func = _enclosing_func(module, op) if op is not None else None
    has = ", ".join(sorted(advertised)) or "none"
    raise KdslCapabilityError(
        f"the {backend_name} backend does not support {cap} ({DESCRIPTION[cap]}), which this "
        f"kernel needs; its capabilities: {has}"
        + (f" (also missing: {', '.join(missing[1:])})" if len(missing) > 1 else ""),
        op.loc if op is not None else None,
        func,
    )


def _scalars(t: Type) -> set[str]:
    """The names of the scalar types ``t`` is made of."""
    if isinstance(t, ScalarType):
        return {str(t)}
    if isinstance(t, ArrayType):
        return _scalars(t.dtype)
    if isinstance(t, VectorType | MatrixType):
        return _scalars(t.elem)
    if isinstance(t, StructType):
        return set().union(*(_scalars(ft) for _, ft in t.fields))
    return set()


def _needs(op: Operation, cap: str) -> bool:
    if cap == "atomics":
        return op.name in _ATOMIC_OPS
    types = [v.type for v in (*op.results, *op.operands)]
    types += [a.type for r in op.regions for a in r.block.args]
    return any(CAPABILITY_OF_SCALAR.get(s) == cap for t in types for s in _scalars(t))


def _first_needing(module: Module, cap: str) -> Operation | None:
    """The first located op that needs ``cap`` (None when none carries a location)."""
    return next((op for op in module.walk() if op.loc is not None and _needs(op, cap)), None)


def _enclosing_func(module: Module, op: Operation) -> str | None:
    for func in module.funcs:
        if any(o is op for o in func.walk()):
            return func.attrs.get("sym_name")
    return None
