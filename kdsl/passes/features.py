"""Feature analysis: what a module uses, so a backend emits only that.

``analyze_features(module)`` is the one analysis every consumer reads: the cuda and
cpu emitters (which emit a helper, type definition or declaration only for a feature
listed here, see ``docs/backends.md``), ``kdsl ir --features`` and the ``features``
pass (which stores the result as ``module.features`` for ``kdsl opt``). It never
changes the IR.

The result, ``Features``, holds the raw lists (op names, op groups, scalar types of
every value, array elements and struct fields included, atomic kinds, math
intrinsics, ``kd.tid`` dimensionalities, struct and handle names) and, in
``Features.names``, the feature vocabulary, one string per feature present:

- ``f16``, ``f64``: a value, array element or struct field of that float type;
  ``int8``, ``int16``, ``int64``: an integer type of that width, signed or unsigned.
- ``vectors``, ``matrices``, ``quaternions``, ``transforms``: a value of that kind;
  ``structs``: a struct type; ``handles``: a geometry handle type.
- ``atomics``: any ``kd.atomic_rmw`` or ``kd.atomic_cas``, with one ``atomic.<kind>``
  per kind used (``add sub min max and or xor exch cas``).
- ``math.<fn>``: each math intrinsic used, by op name (``math.sin``, ``math.erf``...).
- ``local_arrays``: ``kd.local_array`` (thread-local arrays, ``zeros`` in a kernel).
- ``print``: ``kd.print`` (the C library's or the device's ``printf``).
- ``check.bounds``, ``check.finite``: the debug checks ``kd.check_bounds`` and
  ``kd.check_finite`` (inserted by the ``bounds-check`` and ``fp-check`` passes).
- ``tid.<n>d``: an n-dimensional thread index, n >= 2.
- ``loops`` (``scf.for``/``scf.while``), ``control_flow`` (any branch, loop or
  select), ``calls`` (a ``func.call`` left after inlining).
- ``stdlib.<module>``: code inlined from kdsl's standard library module ``random``,
  ``noise``, ``linalg``, ``quat``, ``spatial``, ``transform`` or ``special``, known
  from the ops' source locations (IR parsed without locations lists none).
- ``adjoint``: a kernel's adjoint (a function with ``adjoint_of``); ``tapes``: an
  adjoint that uses one of its hidden tape parameters (memory the runtime allocates).

``"f16" in features`` tests a name. No options.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from functools import cache
from typing import ClassVar

from kdsl.errors import KdslError
from kdsl.ir import Module, Operation
from kdsl.ir.types import (
    ArrayType,
    HandleType,
    MatrixType,
    QuatType,
    ScalarType,
    StructType,
    TransformType,
    Type,
    VectorType,
)
from kdsl.passes.manager import ModulePass

#: The standard library's directory: ops located in a file there are library code.
_STDLIB_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.realpath(__file__))), "stdlib")
#: Flags of ``Features`` that are also feature names.
_FLAGS = ("vectors", "matrices", "quaternions", "transforms", "loops", "control_flow", "calls")
#: Debug-check op -> feature name.
_CHECKS = {"kd.check_bounds": "check.bounds", "kd.check_finite": "check.finite"}
#: The name of an adjoint's tape parameter (``tape<loop>_<leaf>``, see ``tape-dce``).
_TAPE = re.compile(r"tape\d+_\d+")


@dataclass(frozen=True)
class Features:
    """What a module uses (see the module docstring for ``names``, the vocabulary)."""

    ops: frozenset[str] = frozenset()
    groups: frozenset[str] = frozenset()
    scalar_types: frozenset[str] = frozenset()
    atomic_kinds: frozenset[str] = frozenset()
    math: frozenset[str] = frozenset()
    tid_ndims: frozenset[int] = frozenset()
    handles: frozenset[str] = frozenset()
    structs: frozenset[str] = frozenset()
    vectors: bool = False
    matrices: bool = False
    quaternions: bool = False
    transforms: bool = False
    loops: bool = False
    control_flow: bool = False
    calls: bool = False
    #: The feature vocabulary: every name of the module docstring's table that applies.
    names: frozenset[str] = frozenset()

    @property
    def atomics(self) -> bool:
        """True if the module uses any atomic read-modify-write."""
        return bool(self.atomic_kinds)

    def __contains__(self, name: object) -> bool:
        """True if the feature ``name`` (``"f16"``, ``"atomic.add"``...) is listed."""
        return name in self.names

    def require(self, name: str, what: str) -> None:
        """Raise unless the feature ``name`` is listed; ``what`` (a backend's helper or
        declaration) belongs to it. A backend calls this before it emits ``what``."""
        if name not in self.names:
            raise KdslError(
                f"internal error: {what} belongs to the feature {name!r}, which the "
                "feature analysis of the module does not list"
            )

    def uses(self, op_name: str) -> bool:
        """True if an op called ``op_name`` appears."""
        return op_name in self.ops

    def summary(self) -> str:
        """A few readable lines, one per feature that is present."""

        def names(xs) -> str:
            return ", ".join(sorted(map(str, xs))) or "-"

        flags = [name for name in _FLAGS if getattr(self, name)]
        lines = [
            f"ops: {names(self.ops)}",
            f"groups: {names(self.groups)}",
            f"scalar types: {names(self.scalar_types)}",
            f"atomics: {names(self.atomic_kinds)}",
            f"math: {names(self.math)}",
            f"tid ndims: {names(self.tid_ndims)}",
            f"structs: {names(self.structs)}",
            f"handles: {names(self.handles)}",
            f"flags: {names(flags)}",
            f"names: {names(self.names)}",
        ]
        return "\n".join(lines) + "\n"


class _Collector:
    def __init__(self) -> None:
        self.ops: set[str] = set()
        self.groups: set[str] = set()
        self.scalars: set[str] = set()
        self.atomics: set[str] = set()
        self.tid: set[int] = set()
        self.handles: set[str] = set()
        self.structs: set[str] = set()
        self.kinds: set[str] = set()
        self.files: set[str] = set()
        self.seen_types: set[Type] = set()

    def add_type(self, t: Type) -> None:
        if t in self.seen_types:
            return
        self.seen_types.add(t)
        if isinstance(t, ScalarType):
            self.scalars.add(str(t))
        elif isinstance(t, ArrayType):
            self.add_type(t.dtype)
        elif isinstance(t, StructType):
            self.structs.add(t.name)
            for _, ft in t.fields:
                self.add_type(ft)
        elif isinstance(t, HandleType):
            self.handles.add(str(t))
        elif isinstance(t, VectorType | MatrixType):
            self.kinds.add(composite_kind(t))
            self.add_type(t.elem)

    def add_op(self, op: Operation) -> None:
        self.ops.add(op.name)
        if op.opdef.group:
            self.groups.add(op.opdef.group)
        if op.name == "kd.atomic_rmw":
            self.atomics.add(op.attrs["kind"])
        elif op.name == "kd.atomic_cas":
            self.atomics.add("cas")
        elif op.name == "kd.tid":
            self.tid.add(int(op.attrs["ndim"]))
        if op.loc is not None:
            self.files.add(op.loc.file)
        for v in op.results:
            self.add_type(v.type)
        for region in op.regions:
            for a in region.block.args:
                self.add_type(a.type)


def composite_kind(t: Type) -> str:
    """The feature name of a vector or matrix type: vectors, matrices, quaternions, transforms."""
    for cls, kind in ((QuatType, "quaternions"), (TransformType, "transforms"),
                      (MatrixType, "matrices")):  # fmt: skip
        if isinstance(t, cls):
            return kind
    return "vectors"


@cache
def _stdlib_module(file: str) -> str | None:
    """``random`` for ``.../kdsl/stdlib/random.py``; None for a file outside the library."""
    path = os.path.realpath(file) if os.path.isabs(file) else file
    if os.path.dirname(path) != _STDLIB_DIR or not path.endswith(".py"):
        return None
    return os.path.basename(path)[:-3]


def _scalar_names(scalars: set[str]) -> set[str]:
    out = {s for s in ("f16", "f64") if s in scalars}
    for bits in (8, 16, 64):
        if f"i{bits}" in scalars or f"u{bits}" in scalars:
            out.add(f"int{bits}")
    return out


def _autodiff_names(module: Module) -> set[str]:
    """``adjoint``, and ``tapes`` when a hidden tape parameter (past ``hidden_from``) is used."""
    out: set[str] = set()
    for func in module.funcs:
        if "adjoint_of" not in func.attrs:
            continue
        out.add("adjoint")
        hidden = func.regions[0].block.args[func.attrs.get("hidden_from", 0) :]
        if any(a.uses and _TAPE.fullmatch(a.name_hint or "") for a in hidden):
            out.add("tapes")
    return out


def _names(c: _Collector, module: Module, flags: dict[str, bool]) -> frozenset[str]:
    names = _scalar_names(c.scalars)
    names |= {name for name, on in flags.items() if on}
    if c.structs:
        names.add("structs")
    if c.handles:
        names.add("handles")
    if c.atomics:
        names |= {"atomics", *(f"atomic.{k}" for k in c.atomics)}
    names |= {n for n in c.ops if n.startswith("math.")}
    if "kd.print" in c.ops:
        names.add("print")
    if "kd.local_array" in c.ops:
        names.add("local_arrays")
    names |= {_CHECKS[n] for n in c.ops if n in _CHECKS}
    names |= {f"tid.{n}d" for n in c.tid if n > 1}
    names |= {f"stdlib.{m}" for m in map(_stdlib_module, c.files) if m is not None}
    return frozenset(names | _autodiff_names(module))


def analyze_features(module: Module) -> Features:
    """The ``Features`` of ``module`` (see the module docstring)."""
    c = _Collector()
    for op in module.walk():
        c.add_op(op)
    for st in module.structs.values():
        c.add_type(st)
    flags = {
        "vectors": "vectors" in c.kinds,
        "matrices": "matrices" in c.kinds,
        "quaternions": "quaternions" in c.kinds,
        "transforms": "transforms" in c.kinds,
        "loops": bool(c.ops & {"scf.for", "scf.while"}),
        "control_flow": bool(c.ops & {"scf.if", "scf.for", "scf.while", "arith.select"}),
        "calls": "func.call" in c.ops,
    }
    return Features(
        ops=frozenset(c.ops),
        groups=frozenset(c.groups),
        scalar_types=frozenset(c.scalars),
        atomic_kinds=frozenset(c.atomics),
        math=frozenset(n for n in c.ops if n.startswith("math.")),
        tid_ndims=frozenset(c.tid),
        handles=frozenset(c.handles),
        structs=frozenset(c.structs),
        names=_names(c, module, flags),
        **flags,
    )


@dataclass(frozen=True)
class FeaturesPass(ModulePass):
    """Analysis only: stores ``analyze_features(module)`` as ``module.features``."""

    name: ClassVar[str] = "features"

    def apply(self, module: Module) -> bool:
        module.features = analyze_features(module)  # type: ignore[attr-defined]
        return False
