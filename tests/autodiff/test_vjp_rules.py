"""Every VJP rule of the catalog, checked on its own against finite differences.

The harness builds, per op and operand types, a function ``f(operands..., seed) ->
(result, adjoints...)``: it applies the op, then calls the op's rule with a
``VjpContext`` whose primal map is the identity, so the rule's ops land in the same
function. The interp backend runs it; the adjoints are compared with central
differences of ``sum(seed * op(x))`` in float64 at seeded random points, and the
documented singular points are checked to give the documented finite values.
"""

from __future__ import annotations

import itertools
import math
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pytest

from kdsl.backends.interp.program import Program, ThreadContext
from kdsl.compiler import compile_kernel
from kdsl.ir import CATALOG, Builder, Module, new_func, verify_module
from kdsl.ir.types import (
    BOOL,
    F32,
    F64,
    I32,
    ArrayType,
    MatrixType,
    QuatType,
    ScalarType,
    StructType,
    TransformType,
    Type,
    VectorType,
    with_elem,
)
from kdsl.ir.vjp import VjpContext, get_rule, is_differentiable

V2, V3, V4 = (VectorType(n, F64) for n in (2, 3, 4))
M22, M23, M34 = MatrixType(2, 2, F64), MatrixType(2, 3, F64), MatrixType(3, 4, F64)
S = StructType("S", (("x", F64), ("v", V3), ("k", I32)))
ELEMENTWISE = (F64, V3, M22)


# --- harness ----------------------------------------------------------------


class Harness:
    """One op applied to arguments, with its rule's adjoints, compiled for interp."""

    def __init__(
        self,
        name: str,
        types: Sequence[Type],
        attrs: dict | None = None,
        result: Type | None = None,
        module: Module | None = None,
        fname: str = "f",
    ) -> None:
        attrs = dict(attrs or {})
        opdef = CATALOG[name]
        rt = result or opdef.type_rule(list(types), attrs)[0]
        self.types, self.result_type, self.fname = list(types), rt, fname
        m = module or Module()
        for t in (*types, rt):
            if isinstance(t, StructType):
                m.add_struct(t)
        f = new_func(m, fname, [*types, rt], [None] * (len(types) + 1), [], "func")
        block = f.regions[0].block
        b = Builder(block)
        *args, seed = block.args
        op = b.create(name, args, [rt], attrs or None)
        adjs = get_rule(name)(VjpContext(b, lambda v: v), op, [seed])
        assert len(adjs) == len(types)
        for v, a in zip(args, adjs):
            assert a is None or a.type == v.type, f"{name}: adjoint of {v.type} has type {a.type}"
        self.present = [a is not None for a in adjs]
        outs = [op.result, *[a for a in adjs if a is not None]]
        b.create("func.return", outs)
        f.attrs["res_types"] = [v.type for v in outs]
        verify_module(m)
        self.module, self.func = m, f
        program = Program(m)
        self.ctx = ThreadContext(program, program.function(fname), fname)

    def __call__(self, values: Sequence[Any], seed: Any) -> tuple[Any, list[Any]]:
        """The op's result and each operand's adjoint (None where the rule gave none)."""
        with np.errstate(all="ignore"):
            outs = self.ctx.call(self.fname, [*values, seed])
        return self.split(outs)

    def split(self, got: Sequence[Any]) -> tuple[Any, list[Any]]:
        """Function outputs (result, present adjoints) as (result, adjoint or None each)."""
        r, *rest = got
        it = iter(rest)
        return r, [next(it) if p else None for p in self.present]


def _n_float(t: Type) -> int:
    if isinstance(t, StructType):
        return sum(_n_float(ft) for _, ft in t.fields)
    if not is_differentiable(t):
        return 0
    return 1 if isinstance(t, ScalarType) else int(np.prod(t.shape))  # type: ignore[attr-defined]


def flatten(v: Any, t: Type) -> np.ndarray:
    """The float components of a value of ``t`` (zero-length for non-float types)."""
    if isinstance(t, StructType):
        parts = [flatten(x, ft) for x, (_, ft) in zip(v, t.fields)]
        return np.concatenate(parts) if parts else np.zeros(0)
    if not is_differentiable(t):
        return np.zeros(0)
    return np.ravel(np.asarray(v, dtype=np.float64))


def unflatten(flat: np.ndarray, t: Type, like: Any) -> Any:
    """A value of ``t`` with float components ``flat``, other parts from ``like``."""
    if isinstance(t, StructType):
        out, k = [], 0
        for x, (_, ft) in zip(like, t.fields):
            n = _n_float(ft)
            out.append(unflatten(flat[k : k + n], ft, x))
            k += n
        return tuple(out)
    if not is_differentiable(t):
        return like
    dt = t.elem.np_dtype if not isinstance(t, ScalarType) else t.np_dtype  # type: ignore[attr-defined]
    if isinstance(t, ScalarType):
        return dt.type(flat[0])
    return flat.reshape(t.shape).astype(dt)  # type: ignore[attr-defined]


def check_fd(h: Harness, values: list[Any], seed: Any, rtol: float = 1e-5) -> None:
    """Each operand's adjoint equals central differences of sum(seed * op(x))."""
    s = flatten(seed, h.result_type)
    _, adjs = h(values, seed)
    for i, t in enumerate(h.types):
        n = _n_float(t)
        if n == 0:
            assert adjs[i] is None
            continue
        x = flatten(values[i], t)
        fd = np.zeros(n)
        for k in range(n):
            step = 1e-6 * max(1.0, abs(x[k]))
            total = []
            for d in (step, -step):
                xp = x.copy()
                xp[k] += d
                vs = list(values)
                vs[i] = unflatten(xp, t, values[i])
                total.append(float(np.dot(s, flatten(h(vs, seed)[0], h.result_type))))
            fd[k] = (total[0] - total[1]) / (2 * step)
        got = np.zeros(n) if adjs[i] is None else flatten(adjs[i], t)
        scale = 1.0 + np.max(np.abs(fd))
        np.testing.assert_allclose(
            got, fd, rtol=rtol, atol=1e-6 * scale, err_msg=f"operand {i} ({t}) at {values}"
        )


def random_value(rng: np.random.Generator, t: Type, lo: float = -2.0, hi: float = 2.0) -> Any:
    """A random value of ``t``: floats in [lo, hi), int fields 0, bools random."""
    if isinstance(t, StructType):
        return tuple(random_value(rng, ft, lo, hi) for _, ft in t.fields)
    if t == BOOL:
        return np.bool_(rng.random() < 0.5)
    if isinstance(t, ScalarType) and t.is_int:
        return t.np_dtype.type(0)
    return unflatten(rng.uniform(lo, hi, _n_float(t)), t, None)


def _away(rng: np.random.Generator, t: Type, lo: float, hi: float) -> Any:
    """Random magnitudes in [lo, hi) with random signs."""
    v = np.asarray(random_value(rng, t, lo, hi), dtype=np.float64)
    sign = np.where(rng.random(v.shape) < 0.5, -1.0, 1.0)
    return unflatten(np.ravel(v * sign), t, None)


def _off_grid(rng: np.random.Generator, t: Type, step: float = 1.0) -> Any:
    """Values at least 0.1 step from multiples of ``step / 2`` (rounding jumps)."""
    n = _n_float(t)
    k = rng.integers(-3, 3, n)
    frac = rng.choice([0.15, 0.3, 0.65, 0.8], n) + rng.uniform(-0.04, 0.04, n)
    return unflatten((k + frac) * step, t, None)


Sampler = Callable[[np.random.Generator, Sequence[Type]], list[Any]]


def _default(rng: np.random.Generator, ts: Sequence[Type]) -> list[Any]:
    return [random_value(rng, t) for t in ts]


def _each(*samplers: Callable[[np.random.Generator, Type], Any]) -> Sampler:
    return lambda rng, ts: [s(rng, t) for s, t in zip(samplers, ts)]


def _uniform(lo: float, hi: float):
    return lambda rng, t: random_value(rng, t, lo, hi)


def _nonzero(lo: float = 0.5, hi: float = 2.0):
    return lambda rng, t: _away(rng, t, lo, hi)


def _mod_sampler(rng: np.random.Generator, ts: Sequence[Type]) -> list[Any]:
    # a = b * (q + f): a/b stays away from integers, where fmod jumps.
    b = np.asarray(_away(rng, ts[1], 0.7, 1.5), dtype=np.float64)
    q = rng.integers(-2, 3, b.shape) + rng.uniform(0.2, 0.8, b.shape)
    a = np.asarray(b * q)
    if ts[0] != ts[1]:
        raise AssertionError("mod takes one type")
    return [unflatten(np.ravel(a), ts[0], None), unflatten(np.ravel(b), ts[1], None)]


def _index(n: int):
    return lambda rng, t: np.int32(rng.integers(0, n))


# --- the ops and their sample domains ----------------------------------------------


def _spec(name, types, sampler=_default, attrs=None, result=None, tag=""):
    ident = f"{name}[{','.join(map(str, types))}{'->' + str(result) if result else ''}]{tag}"
    return pytest.param(name, tuple(types), sampler, attrs, result, id=ident)


UNARY_DOMAINS: dict[str, Callable[[np.random.Generator, Type], Any]] = {
    "sqrt": _uniform(0.2, 3.0), "cbrt": _nonzero(0.2, 3.0), "exp": _uniform(-2, 2),
    "exp2": _uniform(-2, 2), "log": _uniform(0.2, 3.0), "log2": _uniform(0.2, 3.0),
    "log10": _uniform(0.2, 3.0), "sin": _uniform(-3, 3), "cos": _uniform(-3, 3),
    "tan": _uniform(-1.2, 1.2), "asin": _uniform(-0.9, 0.9), "acos": _uniform(-0.9, 0.9),
    "atan": _uniform(-3, 3), "sinh": _uniform(-2, 2), "cosh": _uniform(-2, 2),
    "tanh": _uniform(-2, 2), "erf": _uniform(-2, 2), "erfc": _uniform(-2, 2),
    "floor": _off_grid, "ceil": _off_grid, "trunc": _off_grid, "round": _off_grid,
    "rint": _off_grid, "abs": _nonzero(0.1, 3.0), "sign": _nonzero(0.1, 3.0),
}  # fmt: skip

BINARY_DOMAINS: dict[str, Sampler] = {
    "arith.add": _default, "arith.sub": _default, "arith.mul": _default,
    "arith.div": _each(_uniform(-2, 2), _nonzero()), "arith.min": _default,
    "arith.max": _default, "arith.mod": _mod_sampler,
    "arith.floordiv": lambda rng, ts: [_off_grid(rng, ts[0]), np.float64(1.0)
                                       if ts[1] == F64 else unflatten(np.ones(_n_float(ts[1])), ts[1], None)],
    "arith.pow": _each(_uniform(0.3, 2.0), _uniform(-2, 2)),
    "math.atan2": _default, "math.copysign": _each(_nonzero(0.1, 2), _nonzero(0.1, 2)),
}  # fmt: skip

SPECS = [
    *[_spec(f"math.{n}", [t], _each(UNARY_DOMAINS[n])) for n in UNARY_DOMAINS for t in ELEMENTWISE],
    *[_spec(n, [t, t], s) for n, s in BINARY_DOMAINS.items() for t in ELEMENTWISE],
    _spec("arith.neg", [V3]),
    # scaling forms of mul and div
    *[_spec("arith.mul", ts) for ts in ([F64, V3], [V3, F64], [F64, M23], [M23, F64])],
    _spec("arith.div", [V3, F64], _each(_uniform(-2, 2), _nonzero())),
    _spec("arith.div", [F64, V3], _each(_uniform(-2, 2), _nonzero())),
    _spec("arith.div", [M22, F64], _each(_uniform(-2, 2), _nonzero())),
    _spec("arith.select", [BOOL, V3, V3]),
    _spec("arith.select", [BOOL, F64, F64]),
    _spec("arith.cast", [I32], result=F64),
    # vec
    _spec("vec.construct", [F64, F64, F64], result=V3),
    _spec("vec.construct", [V2, F64], result=V3),
    _spec("vec.construct", [V2, V2], result=M22),
    _spec("vec.construct", [V4], result=M22),
    _spec("vec.construct", [F64, V3, F64, F64], result=M23),
    _spec("vec.construct", [V3, QuatType(F64)], result=TransformType(F64)),
    _spec("vec.splat", [F64], result=V3),
    _spec("vec.splat", [F64], result=M23),
    _spec("vec.extract", [V3, I32], _each(_uniform(-2, 2), _index(3))),
    _spec("vec.extract", [M23, I32], _each(_uniform(-2, 2), _index(2))),
    _spec("vec.extract", [M23, I32, I32], _each(_uniform(-2, 2), _index(2), _index(3))),
    _spec("vec.insert", [V3, F64, I32], _each(_uniform(-2, 2), _uniform(-2, 2), _index(3))),
    _spec("vec.insert", [M23, V3, I32], _each(_uniform(-2, 2), _uniform(-2, 2), _index(2))),
    _spec(
        "vec.insert",
        [M23, F64, I32, I32],
        _each(_uniform(-2, 2), _uniform(-2, 2), _index(2), _index(3)),
    ),
    _spec("vec.dot", [V3, V3]),
    _spec("vec.dot", [QuatType(F64), QuatType(F64)]),
    _spec("vec.cross", [V3, V3]),
    _spec("vec.length", [V3]),
    _spec("vec.length_sq", [V4]),
    _spec("vec.normalize", [V3]),
    _spec("vec.matmul", [M23, M34]),
    _spec("vec.matmul", [M23, V3]),
    _spec("vec.matmul", [V2, M23]),
    _spec("vec.transpose", [M23]),
    _spec("vec.outer", [V2, V3]),
    # struct
    _spec("struct.construct", [F64, V3, I32], result=S),
    _spec("struct.extract", [S], attrs={"field": "v"}),
    _spec("struct.extract", [S], attrs={"field": "x"}),
    _spec("struct.insert", [S, V3], attrs={"field": "v"}),
    _spec("struct.insert", [S, F64], attrs={"field": "x"}),
]


@pytest.mark.parametrize("name, types, sampler, attrs, result", SPECS)
def test_rule_matches_finite_differences(name, types, sampler, attrs, result):
    h = Harness(name, types, attrs, result)
    rng = np.random.default_rng(zlib.crc32(f"{name}{types}".encode()))
    for _ in range(2):
        values = sampler(rng, types)
        seed = random_value(rng, h.result_type)
        check_fd(h, values, seed)


# --- every op has a rule --------------------------------------------------------

_PROBE_TYPES = (F32, VectorType(3, F32), MatrixType(3, 3, F32), I32, BOOL,
                StructType("P", (("x", F32),)))  # fmt: skip
_EXPLICIT_FLOAT_RESULT = {  # ops whose result type is given, not derived
    "arith.constant": [], "arith.cast": [F32], "vec.construct": [F32, F32, F32],
    "vec.splat": [F32], "struct.construct": [F32],
}  # fmt: skip


def _can_give_float(opdef) -> bool:
    if opdef.type_rule is None:
        return True  # result type is chosen by the builder, floats included
    attrs = {"pred": "lt", "field": "x"}
    for n in range(1, 4):
        for ts in itertools.product(_PROBE_TYPES, repeat=n):
            try:
                res = opdef.type_rule(list(ts), dict(attrs))
            except (TypeError, ValueError, KeyError, IndexError, AttributeError):
                continue
            if any(is_differentiable(t) for t in res):
                return True
    return False


def test_every_float_op_has_a_rule():
    missing = []
    for opdef in CATALOG:
        if opdef.name.split(".")[0] in ("kd", "scf", "func"):
            continue
        if _can_give_float(opdef) and get_rule(opdef.name) is None:
            missing.append(opdef.name)
    assert not missing, f"ops with float results but no VJP rule: {missing}"
    # The probe itself must see the ops it should: a sanity check on its reach.
    assert _can_give_float(CATALOG["vec.dot"]) and not _can_give_float(CATALOG["math.isnan"])
    assert not _can_give_float(CATALOG["arith.cmp"])


@pytest.mark.parametrize("name, types", [
    ("arith.add", [I32, I32]), ("arith.mul", [I32, I32]), ("math.abs", [I32]),
    ("vec.dot", [VectorType(3, I32)] * 2), ("arith.cast", [F64]),
])  # fmt: skip
def test_integer_results_get_no_adjoints(name, types):
    result = I32 if name == "arith.cast" else None
    m = Module()
    f = new_func(m, "f", types, [None] * len(types), [], "func")
    b = Builder(f.regions[0].block)
    op = b.create(name, f.regions[0].block.args, [result] if result else None)
    before = len(f.regions[0].block.ops)
    assert get_rule(name)(VjpContext(b, lambda v: v), op, [op.result]) == [None] * len(types)
    assert len(f.regions[0].block.ops) == before  # and emits nothing


def test_constant_rule_gives_nothing():
    m = Module()
    f = new_func(m, "f", [], [], [], "func")
    b = Builder(f.regions[0].block)
    c = b.constant(1.5, F64)
    assert list(get_rule("arith.constant")(VjpContext(b, lambda v: v), c.op, [c])) == []


# --- casts and float32 ------------------------------------------------------------


@pytest.mark.parametrize("src, dst", [(F32, F64), (F64, F32), (V3, with_elem(V3, F32))])
def test_float_cast_adjoint_is_cast_back(src, dst):
    h = Harness("arith.cast", [src], result=dst)
    rng = np.random.default_rng(0)
    x, seed = random_value(rng, src), random_value(rng, dst)
    _, (adj,) = h([x], seed)
    expected = np.asarray(seed).astype(np.asarray(x).dtype)
    assert np.asarray(adj).dtype == expected.dtype
    np.testing.assert_array_equal(adj, expected)


def _to_f32(t: Type) -> Type:
    if isinstance(t, StructType):
        return StructType(t.name + "32", tuple((n, _to_f32(ft)) for n, ft in t.fields))
    if is_differentiable(t):
        return with_elem(t, F32)
    return t


def _cast_value(v: Any, t: Type) -> Any:
    if isinstance(t, StructType):
        return tuple(_cast_value(x, ft) for x, (_, ft) in zip(v, t.fields))
    return unflatten(flatten(v, t), t, v) if is_differentiable(t) else v


@pytest.mark.parametrize(
    "name, types, sampler, attrs, result",
    [p for p in SPECS if F64 in p.values[1] or V3 in p.values[1]][::3],
)
def test_rules_are_type_generic_float32(name, types, sampler, attrs, result):
    """The same rules build valid float32 IR that agrees with the float64 adjoints."""
    t32 = [_to_f32(t) for t in types]
    h32 = Harness(name, t32, attrs, _to_f32(result) if result else None)
    h64 = Harness(name, types, attrs, result)
    rng = np.random.default_rng(1)
    values = sampler(rng, types)
    seed = random_value(rng, h64.result_type)
    _, a64 = h64(values, seed)
    _, a32 = h32(
        [_cast_value(v, t) for v, t in zip(values, t32)], _cast_value(seed, h32.result_type)
    )
    for x64, x32, t in zip(a64, a32, types):
        assert (x64 is None) == (x32 is None)
        if x64 is not None:
            np.testing.assert_allclose(
                flatten(x32, _to_f32(t)), flatten(x64, t), rtol=2e-4, atol=2e-5
            )


# --- documented singular and non-smooth points -----------------------------------

NAN, INF = math.nan, math.inf


def _v(*xs: float) -> np.ndarray:
    return np.array(xs, dtype=np.float64)


SINGULAR = [
    ("math.sqrt", [F64], [0.0], [0.0]),
    ("math.sqrt", [V3], [_v(0, 4, 1)], [_v(0, 0.25, 0.5)]),
    ("math.cbrt", [F64], [0.0], [0.0]),
    ("math.cbrt", [F64], [-0.0], [0.0]),
    ("math.log", [F64], [0.0], [0.0]),
    ("math.log2", [V3], [_v(0, 1, 2)], [_v(0, 1 / math.log(2), 0.5 / math.log(2))]),
    ("math.log10", [F64], [0.0], [0.0]),
    ("math.asin", [F64], [1.0], [0.0]),
    ("math.asin", [F64], [-1.0], [0.0]),
    ("math.asin", [F64], [1.5], [0.0]),
    ("math.acos", [V3], [_v(1, 0, -1)], [_v(0, -1, 0)]),
    ("arith.pow", [F64, F64], [0.0, 0.5], [0.0, 0.0]),
    ("arith.pow", [F64, F64], [0.0, 0.0], [0.0, 0.0]),
    ("arith.pow", [F64, F64], [0.0, 1.0], [1.0, 0.0]),
    ("arith.pow", [F64, F64], [0.0, 2.0], [0.0, 0.0]),
    ("arith.pow", [F64, F64], [-2.0, 2.0], [-4.0, 0.0]),
    (
        "arith.pow",
        [V3, V3],
        [_v(0, 0, 2), _v(0.5, 1, 3)],
        [_v(0, 1, 12), _v(0, 0, 8 * math.log(2))],
    ),
    ("math.atan2", [F64, F64], [0.0, 0.0], [0.0, 0.0]),
    ("math.atan2", [V2, V2], [_v(0, 1), _v(0, 0)], [_v(0, 0), _v(0, -1)]),
    ("vec.length", [V3], [_v(0, 0, 0)], [_v(0, 0, 0)]),
    ("vec.normalize", [V3], [_v(0, 0, 0)], [_v(0, 0, 0)]),
    ("math.abs", [F64], [0.0], [1.0]),
    ("math.abs", [V3], [_v(-0.0, -3, 2)], [_v(1, -1, 1)]),
    ("math.copysign", [F64, F64], [0.0, -2.0], [-1.0, None]),
    ("arith.min", [F64, F64], [1.0, 1.0], [0.0, 1.0]),
    ("arith.max", [F64, F64], [1.0, 1.0], [0.0, 1.0]),
    ("arith.min", [F64, F64], [0.0, -0.0], [0.0, 1.0]),
    ("arith.min", [F64, F64], [-0.0, 0.0], [0.0, 1.0]),
    ("arith.min", [F64, F64], [NAN, 2.0], [0.0, 1.0]),
    ("arith.min", [F64, F64], [2.0, NAN], [1.0, 0.0]),
    ("arith.max", [V3, V3], [_v(NAN, 1, 5), _v(2, NAN, 5)], [_v(0, 1, 0), _v(1, 0, 1)]),
    ("arith.min", [F64, F64], [NAN, NAN], [0.0, 1.0]),
    ("arith.mod", [F64, F64], [3.0, 0.0], [1.0, 0.0]),
    ("arith.floordiv", [F64, F64], [3.0, 0.0], [None, None]),
    ("math.floor", [F64], [2.0], [None]),
    ("math.round", [F64], [2.5], [None]),
    ("math.sign", [F64], [0.0], [None]),
]


@pytest.mark.parametrize(
    "name, types, values, expected", SINGULAR, ids=[f"{s[0]}{s[2]}" for s in SINGULAR]
)
def test_singular_points_give_documented_values(name, types, values, expected):
    h = Harness(name, types)
    seed = unflatten(np.ones(_n_float(h.result_type)), h.result_type, None)
    _, adjs = h(
        [
            unflatten(np.ravel(np.asarray(v, dtype=np.float64)), t, None)
            for v, t in zip(values, types)
        ],
        seed,
    )
    for got, want in zip(adjs, expected):
        if want is None:
            assert got is None
            continue
        assert np.all(np.isfinite(got))
        np.testing.assert_array_equal(np.asarray(got, dtype=np.float64), want)


# --- structs ------------------------------------------------------------------


def test_struct_adjoint_keeps_array_fields_and_zeros_the_rest():
    """A struct holding an array: its adjoint is built without a zero array."""
    t = StructType("T", (("a", ArrayType(F64, 1)), ("k", I32), ("x", F64), ("s", S)))
    h = Harness("struct.extract", [t], {"field": "x"})
    arr = np.arange(3.0)
    s_val = (np.float64(1), np.zeros(3), np.int32(4))
    _, (adj,) = h([(arr, np.int32(7), np.float64(2.0), s_val)], np.float64(5.0))
    assert adj[0] is arr and adj[1] == 0 and adj[2] == 5.0
    assert adj[3][0] == 0 and not adj[3][1].any() and adj[3][2] == 0


# --- the guards lower on a compiled backend ---------------------------------------

CPU_SPECS = [
    *[(n, ts) for n, ts, _vals, _want in SINGULAR],
    ("vec.extract", [M23, I32, I32]),
    ("vec.insert", [M23, V3, I32]),
    ("vec.matmul", [V2, M23]),
    ("vec.construct", [F64, V3, F64, F64], M23),
    ("arith.div", [F64, V3]),
]


def _array_value(rng: np.random.Generator, t: Type, n: int) -> np.ndarray:
    if isinstance(t, ScalarType) and t.is_int:
        return np.zeros(n, np.int32)  # index 0 is valid for every shape here
    return rng.uniform(-2, 2, (n, *getattr(t, "shape", ()))).astype(np.float64)


def test_rules_run_the_same_on_cpu():
    """One kernel calls every rule's function; cpu agrees with interp, NaNs included."""
    from kdsl.backends.cpu import BACKEND as CPU
    from kdsl.backends.interp import BACKEND as INTERP

    m = Module()
    hs = [
        Harness(sp[0], sp[1], None, sp[2] if len(sp) > 2 else None, m, f"f{i}")
        for i, sp in enumerate(CPU_SPECS)
    ]
    k = new_func(m, "k", [], [], [], "kernel")
    blk = k.regions[0].block
    b = Builder(blk)
    tid = b.create("kd.tid", [], [I32], {"dim": 0, "ndim": 1}).result
    for h in hs:
        ins = []
        for t in h.func.regions[0].block.args:
            ins.append(b.value("kd.load", blk.add_arg(ArrayType(t.type, 1)), tid))
        call = b.create("func.call", ins, h.func.attrs["res_types"], {"callee": h.fname})
        for r in call.results:
            b.create("kd.store", [r, blk.add_arg(ArrayType(r.type, 1)), tid])
    b.create("func.return", [])
    verify_module(m)

    n = 3
    rng = np.random.default_rng(3)
    inputs = []
    for h, (_name, types, vals, _want) in zip(hs, SINGULAR, strict=False):
        args = [_array_value(rng, t, n) for t in (*types, h.result_type)]
        for a, v in zip(args, vals):
            a[0] = v  # thread 0 at the singular point, the others at random points
        args[-1][:] = 1.0
        inputs.append(args)
    for h in hs[len(SINGULAR) :]:
        inputs.append([_array_value(rng, t, n) for t in (*h.types, h.result_type)])

    def run(backend):
        flat = []
        for h, args in zip(hs, inputs):
            flat += [a.copy() for a in args]
            flat += [_array_value(rng, t, n) * 0 for t in h.func.attrs["res_types"]]
        backend.launch(compile_kernel(backend, m, "k", {"optimize": False}), (n,), flat)
        return flat

    got, want = run(CPU), run(INTERP)
    assert sum(np.count_nonzero(w) for w in want) > 100  # the outputs were written
    for a, w in zip(got, want):
        np.testing.assert_allclose(a, w, rtol=1e-12, atol=1e-12, equal_nan=True)
