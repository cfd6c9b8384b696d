"""The state CUDA C generation works with: the module's helpers and one function's lines.

``Source`` collects what the whole translation unit needs, each piece once and
only when some op asks for it (``need``): type definitions, scalar helpers,
atomics, the debug record. It holds the module's feature analysis
(``kdsl.passes.features``): a piece that belongs to a feature (the ``kd_f16`` type
for ``f16``, a vector type for ``vectors``, a struct for ``structs``...) is made
only when the analysis lists that feature, so the analysis is the one account of
what a unit holds. ``FuncEmitter`` writes one kernel or function body:
each IR value becomes a C variable ``v<n>``; each line remembers the source
location of the op it came from, so ``lower`` can put ``#line`` directives in.

A lowering (an entry of ``ops.TABLE``) is ``fn(em, op)`` and returns the C
expressions of ``op``'s results (a list, one string, or None). A returned
expression is bound to a fresh variable declared on its own line; lowerings of
statements (stores, control flow) write lines through ``em.line``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from kdsl.backends.base import split_block
from kdsl.backends.cuda import ctypes_ as CT
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Block, Loc, Module, Operation, Value
from kdsl.passes.features import Features, analyze_features, composite_kind

Lowering = Callable[["FuncEmitter", Operation], Any]


class Source:
    """Everything one generated translation unit shares (see the module docstring)."""

    def __init__(
        self,
        module: Module,
        table: dict[str, Lowering],
        debug: bool = False,
        features: Features | None = None,
    ) -> None:
        self.module = module
        self.table = table
        self.debug = debug
        #: What the module uses (computed here unless the caller has it already).
        self.features = analyze_features(module) if features is None else features
        #: key -> C text, in dependency order (a piece is added after what it needs).
        self.pieces: dict[str, str] = {}
        self._making: set[str] = set()
        self.struct_names: dict[T.StructType, str] = {}
        #: IR function symbol -> C name (kernels and functions).
        self.func_names: dict[str, str] = {}
        self.funcs_todo: list[str] = []

    @property
    def uses_f16(self) -> bool:
        """True if the module has float16 values (the unit then defines ``kd_f16``)."""
        return "f16" in self.features

    def need(self, key: str, make: Callable[[], str], feature: str | None = None) -> None:
        """Add the piece ``key`` (text from ``make()``) unless it is there already.

        A piece of a ``feature`` is made only when the feature analysis lists it.
        """
        if key in self.pieces or key in self._making:
            return
        if feature is not None:
            self.features.require(feature, f"the cuda backend's piece {key!r}")
        self._making.add(key)
        text = make()  # may need other pieces first; they land before this one
        self._making.discard(key)
        self.pieces[key] = text

    def has(self, key: str) -> bool:
        return key in self.pieces

    # -- names ------------------------------------------------------------------
    def func_name(self, symbol: str) -> str:
        """The C name of IR function ``symbol`` (mangled; see ``ctypes_``)."""
        name = self.func_names.get(symbol)
        if name is None:
            name = f"k_{CT.sanitize(symbol)}_{len(self.func_names)}"
            self.func_names[symbol] = name
        return name

    # -- types ------------------------------------------------------------------
    def ctype(self, t: T.Type) -> str:
        """The C type of ``t``, its definition added on first use."""
        from kdsl.backends.cuda import helpers  # helpers imports this module

        if isinstance(t, T.ScalarType):
            if t.is_float and t.bits == 16:
                helpers.need_f16(self)
            return CT.scalar_c(t)
        if isinstance(t, T.VectorType | T.MatrixType):
            name = CT.composite_name(t)
            elem = self.ctype(t.elem)
            self.need(
                f"type:{name}",
                lambda: f"struct {name} {{ {elem} c[{CT.count(t)}]; }};",
                composite_kind(t),
            )
            return name
        if isinstance(t, T.StructType):
            return self._struct(t)
        if isinstance(t, T.ArrayType):
            name = CT.array_name(t.ndim)
            nd = t.ndim
            self.need(
                f"type:{name}",
                lambda: (
                    f"struct {name} {{ char *data; long long shape[{nd}]; "
                    f"long long strides[{nd}]; }};"
                ),
            )
            return name
        if isinstance(t, T.HandleType):
            return "unsigned long long"
        raise KdslCapabilityError(f"the cuda backend cannot represent values of type {t}")

    def ret_struct(self, types: Sequence[T.Type]) -> str:
        """The struct a function returning several values returns (fields r0, r1...)."""
        cs = [self.ctype(t) for t in types]
        name = "kd_ret_" + "_".join(CT.sanitize(c) for c in cs)
        fields = " ".join(f"{c} r{i};" for i, c in enumerate(cs))
        self.need(f"type:{name}", lambda: f"struct {name} {{ {fields} }};", "calls")
        return name

    def _struct(self, t: T.StructType) -> str:
        name = self.struct_names.get(t)
        if name is None:
            name = f"k_{CT.sanitize(t.name)}_{len(self.struct_names)}"
            self.struct_names[t] = name

        def make() -> str:
            fields = " ".join(f"{self.ctype(ft)} f{i};" for i, (_, ft) in enumerate(t.fields))
            # A declared alignment lets NVRTC load the struct with 16-byte vector loads.
            align = f"__align__({t.align}) " if t.align else ""
            return f"struct {align}{name} {{ {fields} }};"

        self.need(f"type:{name}", make, "structs")
        return name


class FuncEmitter:
    """Writes the body of one kernel or function; see the module docstring."""

    def __init__(self, src: Source, func: Operation, is_kernel: bool) -> None:
        self.src = src
        self.func = func
        self.is_kernel = is_kernel
        self.symbol: str = func.attrs["sym_name"]
        #: (indent, text, loc) per line of the body.
        self.lines: list[tuple[int, str, Loc | None]] = []
        self.depth = 1
        self.names: dict[Value, str] = {}
        self.counter = 0
        self.loc: Loc | None = func.loc
        #: C expressions of the n-d thread index components, when a kernel uses them.
        self.tid_parts: list[str] = []
        #: Array parameters whose element offsets are summed in 32 bits (a fast entry).
        self.narrow: frozenset[Value] = frozenset()
        #: Array parameters loaded through the read-only data cache (a fast entry).
        self.read_only: frozenset[Value] = frozenset()
        #: C return type of a function (for debug-mode early returns).
        self.ret_type = "void"

    # -- values -------------------------------------------------------------------
    def fresh(self) -> str:
        name = f"v{self.counter}"
        self.counter += 1
        return name

    def bind(self, v: Value, expr: str) -> None:
        self.names[v] = expr

    def get(self, v: Value) -> str:
        """The C expression of IR value ``v``."""
        return self.names[v]

    def args(self, op: Operation) -> list[str]:
        return [self.names[v] for v in op.operands]

    def ctype(self, t: T.Type) -> str:
        return self.src.ctype(t)

    def declare(self, t: T.Type, expr: str | None = None) -> str:
        """A new variable of type ``t`` (initialized to ``expr`` when given); its name."""
        name = self.fresh()
        init = f" = {expr}" if expr is not None else ""
        self.line(f"{self.ctype(t)} {name}{init};")
        return name

    # -- lines ----------------------------------------------------------------------
    def line(self, text: str, loc: Loc | None = None) -> None:
        self.lines.append((self.depth, text, loc if loc is not None else self.loc))

    def open(self, text: str) -> None:
        """A line ending in ``{``; what follows is indented."""
        self.line(text)
        self.depth += 1

    def close(self, text: str = "}") -> None:
        self.depth -= 1
        self.line(text)

    # -- lowering -------------------------------------------------------------------
    def lower_op(self, op: Operation) -> None:
        rule = self.src.table.get(op.name)
        if rule is None:
            raise KdslCapabilityError(f"the cuda backend cannot lower {op.name} yet", op.loc)
        saved, self.loc = self.loc, op.loc
        try:
            out = rule(self, op)
            if out is None:
                out = []
            elif isinstance(out, str):
                out = [out]
            for r, expr in zip(op.results, out):
                # Names and literals are used where they are needed; the rest gets a variable.
                if _is_name(expr) or op.name == "arith.constant":
                    self.bind(r, expr)
                else:
                    self.bind(r, self.declare(r.type, expr))
        finally:
            self.loc = saved

    def lower_block(self, block: Block, args: Sequence[str] = ()) -> list[str]:
        """Lower ``block`` with its arguments bound; gives its terminator's operands."""
        for a, name in zip(block.args, args):
            self.bind(a, name)
        ops, yielded = split_block(block)
        for op in ops:
            self.lower_op(op)
        return [self.names[v] for v in yielded]

    def assign(
        self, targets: Sequence[str], values: Sequence[str], types: Sequence[T.Type]
    ) -> None:
        """``targets = values`` as a parallel assignment (values may read targets)."""
        pairs = [(t, v, ty) for t, v, ty in zip(targets, values, types) if t != v]
        if len(pairs) <= 1 or not {v for _, v, _ in pairs} & set(targets):
            for t, v, _ in pairs:
                self.line(f"{t} = {v};")
            return
        temps = [self.declare(ty, v) for _, v, ty in pairs]
        for (t, _, _), tmp in zip(pairs, temps):
            self.line(f"{t} = {tmp};")


def _is_name(expr: str) -> bool:
    """True for a plain variable name (no need to copy it into a new one)."""
    return expr.isidentifier() and expr[0] == "v" and expr[1:].isdigit()
