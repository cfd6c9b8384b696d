"""Hypothesis strategies for valid fuzzed kdsl programs (``programs()``).

The generator keeps an environment of typed local names and draws statements and
expressions by type, so every program it builds type-checks: operands share a type,
mixes of widths go through explicit casts, names are read only where they are surely
assigned, ``break``/``continue`` only appear in loops, and every path writes ``out[i]``
exactly once (so the adjoint is well defined). Values stay bounded (divisions by
``1 + x*x``, square roots of ``1 + x*x``, casts of clamped floats) so the backends are
compared where the language defines the result.

Types are short names: ``F`` (the program's float type), ``f16``/``f32``/``f64``,
``i8``..``i64``, ``u8``..``u64``, ``bool``, ``V3``, ``M33``, ``Q`` (quaternion), ``TF``
(transform) and ``S`` (the ``Params`` struct, with a nested ``Inner``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hypothesis import strategies as st

from kdsl.testing.fuzz.program import Assign, For, If, Inputs, Line, N, Program, While

FLOATS = ("f16", "f32", "f64")
INTS = ("i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64")
#: The constructor spelling of each scalar type.
CTOR = {
    "F": "F", "f16": "wp.float16", "f32": "wp.float32", "f64": "wp.float64",
    "i8": "wp.int8", "i16": "wp.int16", "i32": "wp.int32", "i64": "wp.int64",
    "u8": "wp.uint8", "u16": "wp.uint16", "u32": "wp.uint32", "u64": "wp.uint64",
}  # fmt: skip
LOCAL_TYPES = (
    "F",
    "F",
    "F",
    "i32",
    "i32",
    "bool",
    "V3",
    "V3",
    "M33",
    "Q",
    "TF",
    "S",
    *INTS,
    *FLOATS,
)

#: Every language feature the generator can use; ``programs(features=...)`` picks a subset.
ALL_FEATURES = frozenset(
    {"widths", "vectors", "matrices", "quats", "transforms", "structs", "funcs", "static_for",
     "dynamic_for", "while", "break", "return", "atomics", "select"}
)  # fmt: skip

SMALL_FLOATS = (0.0, 0.5, 1.0, 1.5, 2.0, -1.0, -0.25, 3.0)


@dataclass
class Gen:
    """The state of one program's generation: draws, features, names in scope."""

    draw: Any
    features: frozenset[str]
    differentiable: bool
    env: dict[str, list[str]] = field(default_factory=dict)
    uses: set[str] = field(default_factory=set)
    counter: int = 0
    loop_depth: int = 0
    #: Loop variables: readable, never assigned (a loop owns its counter).
    readonly: set[str] = field(default_factory=set)

    # ------------------------------------------------------------------ helpers

    def has(self, feature: str) -> bool:
        return feature in self.features

    def fresh(self, prefix: str = "v") -> str:
        self.counter += 1
        return f"{prefix}{self.counter}"

    def pick(self, options: list) -> Any:
        return self.draw(st.sampled_from(options))

    def flag(self) -> bool:
        return self.draw(st.booleans())

    def locals_of(self, t: str) -> list[str]:
        return self.env.get(t, [])

    def bind(self, t: str, name: str) -> None:
        self.env.setdefault(t, []).append(name)

    def scoped(self) -> dict[str, list[str]]:
        return {t: list(names) for t, names in self.env.items()}

    # ------------------------------------------------------------------ expressions

    def expr(self, t: str, depth: int) -> str:
        """An expression of type ``t`` (``depth`` bounds its nesting)."""
        if t == "F":
            return self.float_expr(depth)
        if t in FLOATS:
            return self.width_float(t, depth)
        if t in INTS:
            return self.int_expr(t, depth)
        if t == "bool":
            return self.bool_expr(depth)
        return getattr(self, f"expr_{t}")(depth)

    def const(self, t: str) -> str:
        if t in ("F", *FLOATS):
            return f"{CTOR[t]}({self.pick(list(SMALL_FLOATS))!r})"
        lo = 0 if t.startswith("u") else -9
        return f"{CTOR[t]}({self.draw(st.integers(lo, 9))})"

    def float_expr(self, depth: int) -> str:
        leaves = ["xs[i]", "const", "local"]
        if self.has("structs"):
            leaves += ["p.a", "p.inner.w", "s_local"]
            if not self.differentiable:  # kdsl does not differentiate reads of struct arrays
                leaves.append("ps[i % 3].a")
        if self.has("vectors"):
            leaves.append("component")
        if depth <= 0:
            choice = self.pick(leaves)
        else:
            ops = ["leaf", "bin", "bin", "div", "unary", "minmax", "cast_int", "ifexp", "fmod"]
            ops.append("atan2")
            if self.has("widths") and not self.differentiable:
                # A round trip through a narrower float is piecewise constant: its
                # finite differences are 0 where the tape passes the gradient through.
                ops.append("cast_width")
            if self.has("select"):
                ops.append("select")
            if self.has("funcs"):
                ops += ["g", "gloop"] + (["sf"] if self.has("structs") else [])
            if self.has("vectors"):
                ops += ["dot", "length"]
            if self.has("matrices"):
                ops += ["det", "melem"]
            if self.has("transforms"):
                ops.append("tpoint")
            choice = self.pick(ops)
            if choice == "leaf":
                choice = self.pick(leaves)
        d = depth - 1
        if choice == "xs[i]":
            return "xs[i]"
        if choice == "const":
            return self.const("F")
        if choice == "local":
            names = self.locals_of("F")
            return self.pick(names) if names else "xs[i]"
        if choice in ("p.a", "p.inner.w", "ps[i % 3].a"):
            self.uses.add("Params")
            return choice
        if choice == "s_local":
            names = self.locals_of("S")
            if not names:
                return "p.a"
            return f"{self.pick(names)}.{self.pick(['a', 'inner.w'])}"
        if choice == "component":
            return f"{self.expr_V3(0)}[{self.draw(st.integers(0, 2))}]"
        if choice == "bin":
            op = self.pick(["+", "-", "*"])
            return f"({self.float_expr(d)} {op} {self.float_expr(d)})"
        if choice == "div":
            b = self.float_expr(d)
            return f"({self.float_expr(d)} / (F(1.0) + {b} * {b}))"
        if choice == "unary":
            fn = self.pick(["wp.sin", "wp.cos", "wp.abs", "-", "sqrt1", "wp.tanh", "exp", "log1",
                            "wp.floor", "wp.atan", "clamp"])  # fmt: skip
            a = self.float_expr(d)
            if fn == "sqrt1":
                return f"wp.sqrt(F(1.0) + {a} * {a})"
            if fn == "exp":  # bounded argument: no overflow in any width
                return f"wp.exp(wp.sin({a}))"
            if fn == "log1":
                return f"wp.log(F(1.0) + {a} * {a})"
            if fn == "clamp":
                return f"wp.clamp({a}, F(-1.0), F(2.0))"
            return f"-({a})" if fn == "-" else f"{fn}({a})"
        if choice == "minmax":
            fn = self.pick(["wp.min", "wp.max"])
            return f"{fn}({self.float_expr(d)}, {self.float_expr(d)})"
        if choice == "ifexp":
            return f"({self.float_expr(d)} if {self.bool_expr(d)} else {self.float_expr(d)})"
        if choice == "fmod":
            return f"({self.float_expr(d)} % F({self.pick([0.75, 1.5, -2.0])}))"
        if choice == "atan2":
            return f"wp.atan2({self.float_expr(d)}, F(1.0) + wp.abs({self.float_expr(d)}))"
        if choice == "cast_int":
            return f"F({self.int_expr('i32', d)})"
        if choice == "cast_width":
            w = self.pick(list(FLOATS))
            return f"F({self.width_float(w, d)})"
        if choice == "select":
            fn = self.pick(["wp.select", "wp.where"])
            return f"{fn}({self.bool_expr(d)}, {self.float_expr(d)}, {self.float_expr(d)})"
        if choice == "g":
            self.uses.add("g")
            return f"g({self.float_expr(d)}, {self.float_expr(d)})"
        if choice == "gloop":
            self.uses.add("gloop")
            return f"gloop({self.float_expr(d)}, ns[i] % wp.int32(4))"
        if choice == "sf":
            self.uses.update(("sf", "Params"))
            return f"sf({self.expr_S(d)}, {self.float_expr(d)})"
        if choice == "dot":
            return f"wp.dot({self.expr_V3(d)}, {self.expr_V3(d)})"
        if choice == "length":
            return f"wp.length({self.expr_V3(d)})"
        if choice == "det":
            return f"wp.determinant({self.expr_M33(d)})"
        if choice == "melem":
            r, c = self.draw(st.integers(0, 2)), self.draw(st.integers(0, 2))
            return f"{self.expr_M33(d)}[{r}, {c}]"
        if choice == "tpoint":
            return f"wp.transform_point({self.expr_TF(d)}, {self.expr_V3(d)})[{self.draw(st.integers(0, 2))}]"
        raise AssertionError(choice)

    def width_float(self, t: str, depth: int) -> str:
        """A float of width ``t``: a cast of an F expression, a constant, a local, or an op."""
        names = self.locals_of(t)
        choice = self.pick(["cast", "const", "op"] + (["local"] if names else []))
        if choice == "local":
            return self.pick(names)
        if choice == "const" or depth <= 0:
            return self.const(t)
        if choice == "cast":
            return f"{CTOR[t]}({self.float_expr(depth - 1)})"
        op = self.pick(["+", "-", "*"])
        return f"({self.width_float(t, depth - 1)} {op} {self.width_float(t, depth - 1)})"

    def int_expr(self, t: str, depth: int) -> str:
        names = self.locals_of(t)
        leaves = ["const"] + (["local"] if names else [])
        if t == "i32":
            leaves += ["i", "ns[i]"] + (["p.n"] if self.has("structs") else [])
        if depth <= 0:
            choice = self.pick(leaves)
        else:
            choice = self.pick(["leaf", "bin", "bin", "bits", "divmod", "minmax", "cast", "shift", "from_bool"]
                               + (["g"] if self.has("funcs") and t == "i32" else []))  # fmt: skip
            if choice == "leaf":
                choice = self.pick(leaves)
        d = depth - 1
        if choice == "const":
            return self.const(t)
        if choice == "local":
            return self.pick(names)
        if choice in ("i", "ns[i]"):
            return choice
        if choice == "p.n":
            self.uses.add("Params")
            return "p.n"
        if choice == "bin":
            op = self.pick(["+", "-", "*"])
            return f"({self.int_expr(t, d)} {op} {self.int_expr(t, d)})"
        if choice == "bits":
            op = self.pick(["&", "|", "^"])
            return f"({self.int_expr(t, d)} {op} {self.int_expr(t, d)})"
        if choice == "divmod":
            op = self.pick(["%", "//"])
            return f"({self.int_expr(t, d)} {op} {CTOR[t]}({self.draw(st.integers(1, 7))}))"
        if choice == "shift":
            op = self.pick(["<<", ">>"])
            return f"({self.int_expr(t, d)} {op} {CTOR[t]}({self.draw(st.integers(0, 3))}))"
        if choice == "minmax":
            fn = self.pick(["wp.min", "wp.max"])
            return f"{fn}({self.int_expr(t, d)}, {self.int_expr(t, d)})"
        if choice == "g":
            self.uses.add("g")
            return f"g({self.int_expr(t, d)}, {self.int_expr(t, d)})"
        if choice == "from_bool":
            return f"{CTOR[t]}({self.bool_expr(d)})"
        # a cast: from another integer width, or from a clamped float (in range for t)
        if self.has("widths") and self.flag():
            other = self.pick(list(INTS))
            return f"{CTOR[t]}({self.int_expr(other, d)})"
        lo = "F(0.0)" if t.startswith("u") else "F(-100.0)"
        return f"{CTOR[t]}(wp.clamp({self.float_expr(d)}, {lo}, F(100.0)))"

    def bool_expr(self, depth: int) -> str:
        names = self.locals_of("bool")
        choice = self.pick(["fcmp", "icmp"] + (["local"] if names else [])
                           + (["not", "andor"] if depth > 0 else []))  # fmt: skip
        d = max(depth - 1, 0)
        if choice == "local":
            return self.pick(names)
        if choice == "fcmp":
            op = self.pick(["<", ">", "<=", ">="])
            return f"({self.float_expr(d)} {op} {self.float_expr(d)})"
        if choice == "icmp":
            op = self.pick(["<", "==", "!=", ">="])
            return f"({self.int_expr('i32', d)} {op} {self.int_expr('i32', d)})"
        if choice == "not":
            return f"(not {self.bool_expr(d)})"
        op = self.pick(["and", "or"])
        return f"({self.bool_expr(d)} {op} {self.bool_expr(d)})"

    def expr_V3(self, depth: int) -> str:
        names = self.locals_of("V3")
        leaves = ["ctor"] + (["local"] if names else []) + (["p.v"] if self.has("structs") else [])
        ops = ["add", "scale", "cross", "normalize"]
        if self.has("matrices"):
            ops.append("matvec")
        if self.has("quats"):
            ops.append("rotate")
        if self.has("transforms"):
            ops.append("tvec")
        if self.has("funcs"):
            ops.append("g")
        choice = self.pick(leaves if depth <= 0 else leaves + ops)
        d = depth - 1
        if choice == "ctor":
            if depth <= 0:
                return f"V3({self.const('F')}, {self.float_expr(0)}, {self.const('F')})"
            return f"V3({self.float_expr(d)}, {self.float_expr(d)}, {self.float_expr(d)})"
        if choice == "local":
            return self.pick(names)
        if choice == "p.v":
            self.uses.add("Params")
            return self.pick(["p.v"] if self.differentiable else ["p.v", "ps[i % 3].v"])
        if choice == "add":
            return f"({self.expr_V3(d)} {self.pick(['+', '-'])} {self.expr_V3(d)})"
        if choice == "scale":
            return f"({self.expr_V3(d)} * {self.float_expr(d)})"
        if choice == "cross":
            return f"wp.cross({self.expr_V3(d)}, {self.expr_V3(d)})"
        if choice == "normalize":
            return f"wp.normalize({self.expr_V3(d)} + V3(F(1.0), F(0.0), F(0.0)))"
        if choice == "matvec":
            return f"({self.expr_M33(d)} * {self.expr_V3(d)})"
        if choice == "rotate":
            return f"wp.quat_rotate({self.expr_Q(d)}, {self.expr_V3(d)})"
        if choice == "tvec":
            return f"wp.transform_vector({self.expr_TF(d)}, {self.expr_V3(d)})"
        self.uses.add("g")
        return f"g({self.expr_V3(d)}, {self.float_expr(d)})"

    def expr_M33(self, depth: int) -> str:
        names = self.locals_of("M33")
        leaves = ["identity", "diag"] + (["local"] if names else [])
        choice = self.pick(
            leaves if depth <= 0 else leaves + ["outer", "mul", "add", "transpose", "scale"]
        )
        d = depth - 1
        if choice == "identity":
            return "wp.identity(n=3, dtype=F)"
        if choice == "diag":
            return f"wp.diag({self.expr_V3(max(d, 0))})"
        if choice == "local":
            return self.pick(names)
        if choice == "outer":
            return f"wp.outer({self.expr_V3(d)}, {self.expr_V3(d)})"
        if choice == "mul":
            return f"({self.expr_M33(d)} * {self.expr_M33(d)})"
        if choice == "add":
            return f"({self.expr_M33(d)} + {self.expr_M33(d)})"
        if choice == "transpose":
            return f"wp.transpose({self.expr_M33(d)})"
        return f"({self.expr_M33(d)} * {self.float_expr(d)})"

    def expr_Q(self, depth: int) -> str:
        names = self.locals_of("Q")
        leaves = ["identity", "axis"] + (["local"] if names else [])
        choice = self.pick(leaves if depth <= 0 else leaves + ["mul", "inverse", "normalize"])
        d = depth - 1
        if choice == "identity":
            return "wp.quat_identity(dtype=F)"
        if choice == "axis":
            a = self.float_expr(max(d, 0))
            return f"wp.quat_from_axis_angle(wp.normalize(V3(F(1.0), {a}, F(0.5))), {self.float_expr(max(d, 0))})"
        if choice == "local":
            return self.pick(names)
        if choice == "mul":
            return f"({self.expr_Q(d)} * {self.expr_Q(d)})"
        if choice == "inverse":
            return f"wp.quat_inverse({self.expr_Q(d)})"
        return f"wp.normalize({self.expr_Q(d)})"

    def expr_TF(self, depth: int) -> str:
        names = self.locals_of("TF")
        leaves = ["ctor"] + (["local"] if names else [])
        choice = self.pick(leaves if depth <= 0 else leaves + ["mul", "inverse"])
        d = depth - 1
        if choice == "ctor":
            return f"TF({self.expr_V3(max(d, 0))}, {self.expr_Q(max(d, 0))})"
        if choice == "local":
            return self.pick(names)
        if choice == "mul":
            return f"wp.transform_multiply({self.expr_TF(d)}, {self.expr_TF(d)})"
        return f"wp.transform_inverse({self.expr_TF(d)})"

    def expr_S(self, depth: int) -> str:
        self.uses.add("Params")
        names = self.locals_of("S")
        return self.pick(["p", *([] if self.differentiable else ["ps[i % 3]"]), *names])

    # ------------------------------------------------------------------ statements

    def type_allowed(self, t: str) -> bool:
        need = {
            "V3": "vectors",
            "M33": "matrices",
            "Q": "quats",
            "TF": "transforms",
            "S": "structs",
        }
        if t in need:
            return self.has(need[t])
        if t in FLOATS:
            return self.has("widths") and not self.differentiable
        if t in INTS and t != "i32":
            return self.has("widths")
        return True

    def block(self, depth: int, size: int) -> tuple:
        """A list of up to ``size`` statements; names bound inside stay inside."""
        saved = self.scoped()
        stmts = tuple(self.stmt(depth) for _ in range(self.draw(st.integers(0, size))))
        self.env = saved
        return stmts

    def stmt(self, depth: int) -> Any:
        kinds = ["assign", "assign", "update"]
        if depth > 0:
            kinds.append("if")
            if self.has("static_for"):
                kinds.append("static_for")
            if self.has("dynamic_for"):
                kinds.append("dynamic_for")
            if self.has("while"):
                kinds.append("while")
        if self.loop_depth and self.has("break"):
            kinds += ["break", "continue"]
        if self.has("return"):
            kinds.append("return")
        if self.has("atomics"):
            kinds.append("atomic")
        kind = self.pick(kinds)
        if kind == "assign":
            t = self.pick([t for t in LOCAL_TYPES if self.type_allowed(t)])
            if t == "S":
                return self.struct_local()
            name = self.fresh()
            stmt = Assign(name, self.expr(t, 2))
            self.bind(t, name)
            return stmt
        if kind == "update":
            targets = [
                (t, n)
                for t in ("F", "i32", "V3")
                for n in self.locals_of(t)
                if n not in self.readonly
            ]
            if not targets:
                return (
                    Line(f"wp.atomic_add(iacc, 0, {self.int_expr('i32', 1)})")
                    if self.has("atomics")
                    else Assign("tmp_" + self.fresh(), self.float_expr(1))
                )
            t, name = self.pick(targets)
            if t == "V3" and self.flag():  # a component store
                return Assign(f"{name}[{self.draw(st.integers(0, 2))}]", self.float_expr(1))
            op = self.pick(["+", "-", "*"] if t != "V3" else ["+", "-"])
            return Assign(name, self.expr(t, 1), op)
        if kind == "if":
            cond = self.bool_expr(1)
            body = self.block(depth - 1, 3)
            orelse = self.block(depth - 1, 2) if self.flag() else ()
            return If(cond, body, orelse)
        if kind in ("static_for", "dynamic_for", "while"):
            var = self.fresh("j")
            if kind == "static_for":
                args = str(self.draw(st.integers(1, 3)))
            elif kind == "dynamic_for":
                args = self.pick(["ns[i] % wp.int32(4)", "wp.int32(1), ns[i] % wp.int32(5)", "i"])
            else:
                args = self.pick(["ns[i] % wp.int32(4)", "wp.int32(3)", "i % wp.int32(3)"])
            self.loop_depth += 1
            saved = self.scoped()
            if kind != "while":
                self.bind("i32", var)
                self.readonly.add(var)
            body = self.block(depth - 1, 3)
            self.env = saved
            self.loop_depth -= 1
            return For(var, args, body) if kind != "while" else While(var, args, body)
        if kind in ("break", "continue"):
            return If(self.bool_expr(1), (Line(kind),))
        if kind == "return":
            return If(self.bool_expr(1), (Assign("out[i]", self.float_expr(2)), Line("return")))
        # atomics: integer ones are exact; float add is differentiable, min/max are not
        options = ["iadd", "imax", "imin", "fadd"] + (
            [] if self.differentiable else ["fmax", "fmin"]
        )
        which = self.pick(options)
        if which[0] == "i":
            fn = {"iadd": "atomic_add", "imax": "atomic_max", "imin": "atomic_min"}[which]
            return Line(
                f"wp.{fn}(iacc, {['iadd', 'imax', 'imin'].index(which)}, {self.int_expr('i32', 1)})"
            )
        fn = {"fadd": "atomic_add", "fmax": "atomic_max", "fmin": "atomic_min"}[which]
        return Line(f"wp.{fn}(acc, {['fadd', 'fmax', 'fmin'].index(which)}, {self.float_expr(2)})")

    def live_terms(self) -> tuple[list[str], list[str]]:
        """Every top-level local, as float and int terms the results add up, so what the
        body computed reaches an output (and is compared, and differentiated)."""
        floats: list[str] = []
        ints: list[str] = []
        for t, names in self.env.items():
            for n in names:
                if t == "F":
                    floats.append(n)
                elif t in FLOATS:
                    floats.append(f"F({n})")
                elif t == "V3":
                    floats.append(f"{n}[{self.draw(st.integers(0, 2))}]")
                elif t == "M33":
                    floats.append(f"wp.trace({n})")
                elif t == "Q":
                    floats.append(f"{n}[{self.draw(st.integers(0, 3))}]")
                elif t == "TF":
                    floats.append(f"wp.transform_get_translation({n})[0]")
                elif t == "S":
                    floats.append(f"{n}.a + {n}.inner.w")
                    ints.append(f"wp.int32({n}.inner.k)")
                elif t in INTS or t == "bool":
                    ints.append(n if t == "i32" else f"wp.int32({n})")
        return floats, ints

    def struct_local(self) -> Any:
        """``s = Params()`` then stores to some of its fields (nested ones too), as one ``Seq``."""
        self.uses.add("Params")
        name = self.fresh("s")
        lines = [Assign(name, "Params()")]
        for fld in self.draw(st.lists(st.sampled_from(["a", "v", "n", "inner.w", "inner.k"]),
                                      min_size=1, max_size=4, unique=True)):  # fmt: skip
            t = {"a": "F", "v": "V3", "n": "i32", "inner.w": "F", "inner.k": "i16"}[fld]
            e = self.expr(t, 1) if t != "i16" else f"wp.int16({self.int_expr('i32', 1)})"
            lines.append(Assign(f"{name}.{fld}", e))
        self.bind("S", name)
        return Seq(tuple(lines))


@dataclass(frozen=True)
class Seq:
    """Several statements at one level (a struct built field by field)."""

    stmts: tuple

    def render(self, indent: str) -> list[str]:
        lines: list[str] = []
        for s in self.stmts:
            lines += s.render(indent)
        return lines


@st.composite
def inputs(draw: Any) -> Inputs:
    """Input values: floats in [-2, 2] (some exact), small integers, struct fields."""
    fl = st.one_of(st.sampled_from(SMALL_FLOATS), st.floats(-2.0, 2.0, width=16))
    return Inputs(
        xs=tuple(draw(st.lists(fl, min_size=N, max_size=N))),
        ns=tuple(draw(st.lists(st.integers(-20, 20), min_size=N, max_size=N))),
        pa=draw(fl),
        pv=(draw(fl), draw(fl), draw(fl)),
        pn=draw(st.integers(-5, 5)),
        pw=draw(fl),
        pk=draw(st.integers(-5, 5)),
    )


@st.composite
def programs(
    draw: Any,
    features: frozenset[str] = ALL_FEATURES,
    max_depth: int = 2,
    max_stmts: int = 6,
    differentiable: bool | None = None,
) -> Program:
    """A valid fuzzed program over ``features`` (see ``ALL_FEATURES``)."""
    if differentiable is None:
        differentiable = draw(st.booleans())
    ftype = draw(
        st.sampled_from(
            ["float32", "float64"] if differentiable else ["float32", "float64", "float16"]
        )
    )
    g = Gen(draw, frozenset(features), differentiable)
    body = tuple(g.stmt(max_depth) for _ in range(draw(st.integers(1, max_stmts))))
    float_terms, int_terms = g.live_terms()
    result_f = " + ".join([g.float_expr(2), *float_terms])
    result_i = " ^ ".join([g.int_expr("i32", 1), *int_terms])
    uses = frozenset(g.uses | {"Params"})
    return Program(ftype, body, result_f, result_i, uses, draw(inputs()), differentiable)
