"""The state one op lowering works with: builder, value map, intrinsics, libm.

Each entry of the lowering table (``ops.TABLE``) is ``fn(em, op)`` and returns the
LLVM values of ``op``'s results (a list, one value, or None). It reads operands
through ``em.get`` and emits through ``em.b``; nested regions go through
``em.lower_block``. A vector, matrix or struct value is a ``composite.Parts`` of
scalar LLVM values (never an LLVM vector), ``em.map`` applies a scalar emitter to
each component.

``ModuleState`` holds the module's feature analysis (``kdsl.passes.features``): the
LLVM module declares a C library function only for a feature the analysis lists
(``tanf`` for ``math.tan``, ``printf`` for ``print``), and only once some op calls it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from llvmlite import ir

from kdsl.backends.base import split_block
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import Parts
from kdsl.errors import KdslCapabilityError
from kdsl.ir.core import Block, Module, Operation, Value
from kdsl.passes.features import Features, analyze_features

Lowering = Callable[["Emitter", Operation], Any]

#: The LLVM fast-math flags of a ``fast_math=True`` kernel. ``reassoc`` lets the loop
#: vectorizer split float reductions (the n-body sum over j) into lanes, ``contract``
#: fuses multiply-adds into FMA, ``afn`` and ``arcp`` allow approximate math and
#: reciprocals (``1/sqrt(x)`` becomes a hardware estimate plus a Newton step), ``nsz``
#: ignores the sign of zero. ``nnan`` and ``ninf`` are left out on purpose: with them
#: LLVM may fold away ``isnan``/``isinf`` tests and turn NaN/Inf inputs into poison, so
#: NaN still propagates and the fp checks keep working.
FAST_MATH_FLAGS = ("reassoc", "contract", "afn", "arcp", "nsz")

#: String attributes a fast-math kernel's functions carry for LLVM's code generator
#: (llvmlite's ``FunctionAttributes`` only knows enum attributes, see ``_FastMathAttrs``).
FAST_MATH_FN_ATTRS = (
    ("unsafe-fp-math", "true"),
    ("no-signed-zeros-fp-math", "true"),
    ("approx-func-fp-math", "true"),
)

#: C library functions (other than libm's, see ``Emitter.libm``) -> their feature.
LIBC_FEATURES = {"printf": "print"}


class FastMathBuilder(ir.IRBuilder):
    """An ``IRBuilder`` that puts fast-math flags on every float instruction it emits.

    Only float arithmetic, float compares and calls returning floats get them (LLVM
    rejects the flags elsewhere), so the lowering tables need no fast-math branches.
    """

    def __init__(self, flags: Sequence[str] = FAST_MATH_FLAGS) -> None:
        super().__init__()
        self.fm_flags = tuple(flags)

    def fadd(self, lhs, rhs, name="", flags=()):
        return super().fadd(lhs, rhs, name, flags or self.fm_flags)

    def fsub(self, lhs, rhs, name="", flags=()):
        return super().fsub(lhs, rhs, name, flags or self.fm_flags)

    def fmul(self, lhs, rhs, name="", flags=()):
        return super().fmul(lhs, rhs, name, flags or self.fm_flags)

    def fdiv(self, lhs, rhs, name="", flags=()):
        return super().fdiv(lhs, rhs, name, flags or self.fm_flags)

    def frem(self, lhs, rhs, name="", flags=()):
        return super().frem(lhs, rhs, name, flags or self.fm_flags)

    def fneg(self, arg, name="", flags=()):
        return super().fneg(arg, name, flags or self.fm_flags)

    def fcmp_ordered(self, cmpop, lhs, rhs, name="", flags=()):
        return super().fcmp_ordered(cmpop, lhs, rhs, name, flags or self.fm_flags)

    def fcmp_unordered(self, cmpop, lhs, rhs, name="", flags=()):
        return super().fcmp_unordered(cmpop, lhs, rhs, name, flags or self.fm_flags)

    def call(
        self, fn, args, name="", cconv=None, tail=False, fastmath=(), attrs=(), arg_attrs=None
    ):
        ret = fn.function_type.return_type if isinstance(fn, ir.Function) else None
        if not fastmath and ret is not None and _is_float(ret):
            fastmath = self.fm_flags
        return super().call(fn, args, name, cconv, tail, fastmath, attrs, arg_attrs)


def _is_float(t: ir.Type) -> bool:
    if isinstance(t, ir.VectorType):
        t = t.element
    return isinstance(t, ir.HalfType | ir.FloatType | ir.DoubleType)


class _FastMathAttrs(ir.values.FunctionAttributes):
    """Function attributes plus the string attributes of ``FAST_MATH_FN_ATTRS``."""

    def __bool__(self) -> bool:  # llvmlite prints a function's attributes only when truthy
        return True

    def _to_list(self, ret_type):
        return super()._to_list(ret_type) + [f'"{k}"="{v}"' for k, v in FAST_MATH_FN_ATTRS]


def mark_fast_math(fn: ir.Function) -> None:
    """Give ``fn`` the fast-math string attributes (keeping the attributes it has)."""
    attrs = _FastMathAttrs()
    for a in fn.attributes:
        attrs.add(a)
    fn.attributes = attrs


class ModuleState:
    """What the functions of one LLVM module share: declarations and callees."""

    def __init__(
        self,
        llmod: ir.Module,
        module: Module,
        table: dict[str, Lowering],
        features: Features | None = None,
    ) -> None:
        self.llmod = llmod
        self.module = module
        self.table = table
        #: What the module uses (computed here unless the caller has it already).
        self.features = analyze_features(module) if features is None else features
        self.funcs: dict[str, ir.Function] = {}
        self.pending: list[str] = []  # callees declared but not emitted yet
        #: Debug build: kernels and functions take a pointer to an error record (``checks``).
        self.debug = False
        #: ``fast_math`` kernel option: float ops get ``FAST_MATH_FLAGS``.
        self.fast_math = False

    def declare(self, name: str, fnty: ir.FunctionType) -> ir.Function:
        """The function ``name`` of the module, declared on first use.

        A C library function of ``LIBC_FEATURES`` is declared only when the feature
        analysis lists its feature.
        """
        fn = self.llmod.globals.get(name)
        if fn is None:
            feature = LIBC_FEATURES.get(name)
            if feature is not None:
                self.features.require(feature, f"the cpu backend's declaration of {name}")
            fn = ir.Function(self.llmod, fnty, name)
        return fn


class Emitter:
    """Lowers the ops of one function body; see the module docstring."""

    def __init__(self, state: ModuleState, fn: ir.Function, func_name: str) -> None:
        self.state = state
        self.fn = fn
        self.func_name = func_name
        self.b = FastMathBuilder() if state.fast_math else ir.IRBuilder()
        if state.fast_math:
            mark_fast_math(fn)
        self.values: dict[Value, ir.Value] = {}
        #: The thread's linear index (i32) and n-d index components (i32), when a kernel.
        self.linear: ir.Value | None = None
        self.index: list[ir.Value] = []
        #: A kernel's range-local sums (``local_sums``): atomic adds summed per range.
        self.local_sums: Any = None
        #: Debug builds: the error record (i64*) and, in a kernel, the block that
        #: ends the current thread after a failed check (see ``checks``).
        self.error_record: ir.Value | None = None
        self.abort_block: ir.Block | None = None
        #: A kernel's access group (``loop_md``): its thread body's array loads and
        #: stores join it; None in functions and debug builds.
        self.access_group: Any = None
        #: The kernel's parameters (``loop_md.kernel_arrays``): only their accesses join.
        self.kernel_arrays: frozenset[Value] = frozenset()
        #: Whether constant loops of at most ``loop_md.UNROLL_INSIDE`` trips are emitted
        #: unrolled (a kernel whose thread loop can be vectorized, ``loop_md``).
        self.unroll_inside = False

    # -- values ---------------------------------------------------------------
    def get(self, v: Value) -> Any:
        """The LLVM value (``Parts`` for a vector, matrix or struct) bound to ``v``."""
        return self.values[v]

    def args(self, op: Operation) -> list[Any]:
        """The LLVM values of all operands of ``op``."""
        return [self.values[v] for v in op.operands]

    def bind(self, values: Sequence[Value], llvals: Sequence[Any]) -> None:
        for v, lv in zip(values, llvals):
            self.values[v] = lv

    def new_block(self, name: str) -> ir.Block:
        return self.fn.append_basic_block(name)

    # -- lowering -------------------------------------------------------------
    def lower_op(self, op: Operation) -> None:
        rule = self.state.table.get(op.name)
        if rule is None:
            raise KdslCapabilityError(f"the cpu backend cannot lower {op.name} yet", op.loc)
        out = rule(self, op)
        if out is None:
            out = []
        elif not isinstance(out, list | tuple):
            out = [out]
        self.bind(op.results, out)

    def lower_block(self, block: Block, args: Sequence[Any] = ()) -> list[Any]:
        """Lower ``block`` with its arguments bound; gives its terminator's operands."""
        self.bind(block.args, args)
        ops, yielded = split_block(block)
        for op in ops:
            self.lower_op(op)
        return [self.values[v] for v in yielded]

    # -- helpers --------------------------------------------------------------
    def intrinsic(
        self,
        name: str,
        types: Sequence[ir.Type],
        ret: ir.Type | None = None,
        args: Sequence[ir.Type] | None = None,
    ) -> ir.Function:
        """An overloaded LLVM intrinsic such as ``llvm.sqrt`` for ``types``."""
        full = name + "".join("." + _mangle(t) for t in types)
        fnty = ir.FunctionType(
            ret if ret is not None else types[0], list(args) if args is not None else [types[0]]
        )
        return self.state.declare(full, fnty)

    def call_intrinsic(self, name: str, *vals: ir.Value) -> ir.Value:
        """Call ``llvm.<name>`` overloaded on the type of the first value."""
        t = vals[0].type
        fn = self.intrinsic(name, [t], t, [v.type for v in vals])
        return self.b.call(fn, list(vals))

    def libm(self, name: str, *vals: ir.Value) -> ir.Value:
        """Call the C math function ``name`` (``tan``...) on float scalars.

        ``name`` is also the math op's (the feature ``math.<name>`` must be listed).
        """
        t = vals[0].type
        if isinstance(t, ir.HalfType):
            wide = [self.b.fpext(v, LT.F32) for v in vals]
            return self.b.fptrunc(self.libm(name, *wide), t)
        sym = name + ("f" if isinstance(t, ir.FloatType) else "")
        if sym not in self.state.llmod.globals:
            self.state.features.require(f"math.{name}", f"the cpu backend's call of {sym}")
        fn = self.state.declare(sym, ir.FunctionType(t, [t] * len(vals)))
        return self.b.call(fn, list(vals))

    def map(self, fn: Callable[..., ir.Value], *vals: Any) -> Any:
        """``fn`` applied componentwise: scalars in, scalar out; ``Parts`` in, ``Parts`` out.

        A scalar operand next to vector or matrix operands is used for every component
        (``v * s``).
        """
        n = next((len(v) for v in vals if isinstance(v, Parts)), None)
        if n is None:
            return fn(*vals)
        cols = [v.items if isinstance(v, Parts) else [v] * n for v in vals]
        return Parts(fn(*xs) for xs in zip(*cols))

    def const(self, t: ir.Type, value: Any) -> ir.Value:
        """A constant of the scalar type ``t``."""
        return ir.Constant(t, value)


def I32c(i: int) -> ir.Constant:
    """An ``i32`` constant."""
    return ir.Constant(LT.I32, i)


def _mangle(t: ir.Type) -> str:
    if isinstance(t, ir.VectorType):
        return f"v{t.count}{_mangle(t.element)}"
    if isinstance(t, ir.IntType):
        return f"i{t.width}"
    if isinstance(t, ir.HalfType):
        return "f16"
    if isinstance(t, ir.FloatType):
        return "f32"
    if isinstance(t, ir.DoubleType):
        return "f64"
    if isinstance(t, ir.PointerType):
        return "p0"
    raise TypeError(f"cannot mangle {t}")
