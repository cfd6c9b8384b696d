"""Feature analysis: what a module uses, so a backend emits only that.

``analyze_features(module)`` lists the op names and op groups (``OpDef.group``),
the scalar types of every value (array elements and struct fields included), the
atomic kinds, composite types (vectors, matrices, quaternions, transforms,
structs, handles), math intrinsics by name, loops, branches and the ``kd.tid``
dimensionalities. The ``features`` pass runs it and stores the result on the
module as ``module.features``; it never changes the IR.

No options.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

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


@dataclass(frozen=True)
class Features:
    """What a module uses. Sets hold names (``"f64"``, ``"math.sin"``, ...)."""

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

    @property
    def atomics(self) -> bool:
        """True if the module uses any atomic read-modify-write."""
        return bool(self.atomic_kinds)

    def uses(self, op_name: str) -> bool:
        """True if an op called ``op_name`` appears."""
        return op_name in self.ops

    def summary(self) -> str:
        """A few readable lines, one per feature that is present."""

        def names(xs) -> str:
            return ", ".join(sorted(map(str, xs))) or "-"

        flags = [name for name in ("vectors", "matrices", "quaternions", "transforms",
                                   "loops", "control_flow", "calls") if getattr(self, name)]  # fmt: skip
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
            self.kinds.add(_composite_kind(t))
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
        for v in op.results:
            self.add_type(v.type)
        for region in op.regions:
            for a in region.block.args:
                self.add_type(a.type)


def _composite_kind(t: Type) -> str:
    for cls, kind in ((QuatType, "quaternions"), (TransformType, "transforms"),
                      (MatrixType, "matrices")):  # fmt: skip
        if isinstance(t, cls):
            return kind
    return "vectors"


def analyze_features(module: Module) -> Features:
    """The ``Features`` of ``module`` (see the module docstring)."""
    c = _Collector()
    for op in module.walk():
        c.add_op(op)
    for st in module.structs.values():
        c.add_type(st)
    return Features(
        ops=frozenset(c.ops),
        groups=frozenset(c.groups),
        scalar_types=frozenset(c.scalars),
        atomic_kinds=frozenset(c.atomics),
        math=frozenset(n for n in c.ops if n.startswith("math.")),
        tid_ndims=frozenset(c.tid),
        handles=frozenset(c.handles),
        structs=frozenset(c.structs),
        vectors="vectors" in c.kinds,
        matrices="matrices" in c.kinds,
        quaternions="quaternions" in c.kinds,
        transforms="transforms" in c.kinds,
        loops=bool(c.ops & {"scf.for", "scf.while"}),
        control_flow=bool(c.ops & {"scf.if", "scf.for", "scf.while", "arith.select"}),
        calls="func.call" in c.ops,
    )


@dataclass(frozen=True)
class FeaturesPass(ModulePass):
    """Analysis only: stores ``analyze_features(module)`` as ``module.features``."""

    name: ClassVar[str] = "features"

    def apply(self, module: Module) -> bool:
        module.features = analyze_features(module)  # type: ignore[attr-defined]
        return False
