"""Edge-case semantics of the cpu backend, compared bit for bit with the interp oracle.

Kernels are written as IR text so these tests exercise only the backend.
"""

from __future__ import annotations

import numpy as np
import pytest

from kdsl.backends.cpu import BACKEND as CPU
from kdsl.backends.interp import BACKEND as INTERP
from kdsl.compiler import compile_kernel
from kdsl.ir.parser import parse_module
from kdsl.ir.types import SCALARS

# Inputs include values (1e30, inf) that overflow float16 on purpose.
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")

INTS = {
    "i8": [0, 1, -1, 7, -7, -128, 127, 3, 8, 9],
    "i32": [0, 1, -1, 7, -7, -(2**31), 2**31 - 1, 31, 32, 33],
    "i64": [0, 1, -1, 7, -7, -(2**63), 2**63 - 1, 63, 64, -65],
    "u8": [0, 1, 255, 7, 200, 128, 3, 8, 9, 254],
    "u32": [0, 1, 2**32 - 1, 7, 2**31, 5, 31, 32, 33, 100],
}
FLOATS = [
    0.0,
    -0.0,
    0.5,
    -0.5,
    1.5,
    2.5,
    -2.5,
    1e30,
    -1e30,
    np.inf,
    -np.inf,
    np.nan,
    3.7,
    -3.7,
    65504.0,
    1e-8,
]


def _run(backend, text: str, args: list, n: int) -> None:
    module = parse_module(text)
    compiled = compile_kernel(backend, module, "k", {"optimize": False})
    backend.launch(compiled, (n,), args)


def _same(a: np.ndarray, b: np.ndarray) -> None:
    if a.dtype.kind == "f":
        assert np.array_equal(a, b, equal_nan=True), (a, b)
        num = ~np.isnan(a)  # zeros must match in sign too; NaN signs are unspecified
        assert np.array_equal(np.signbit(a[num]), np.signbit(b[num])), (a, b)
    else:
        np.testing.assert_array_equal(a, b)


def _binary_kernel(op: str, t: str, rt: str | None = None, attrs: str = "") -> str:
    rt = rt or t
    return f"""func.func @k(%a: array<{t}, 1>, %b: array<{t}, 1>, %o: array<{rt}, 1>) -> () {{kind = "kernel"}} {{
  %i = kd.tid {{dim = 0, ndim = 1}} : i32
  %x = kd.load %a, %i : {t}
  %y = kd.load %b, %i : {t}
  %r = {op} %x, %y{attrs} : {rt}
  kd.store %r, %o, %i
  func.return
}}"""


def _pairs(values: list, dtype: str) -> tuple[np.ndarray, np.ndarray]:
    v = np.array(values, dtype=np.float64 if dtype.startswith("f") else object)
    a = np.repeat(v, len(v)).astype(dtype)
    b = np.tile(v, len(v)).astype(dtype)
    return a, b


def _differential(text: str, a: np.ndarray, b: np.ndarray, out_dtype, exact: bool = True) -> None:
    outs = []
    for backend in (CPU, INTERP):
        o = np.zeros(len(a), dtype=out_dtype)
        _run(backend, text, [a.copy(), b.copy(), o], len(a))
        outs.append(o)
    if exact:
        _same(*outs)
    else:  # libm and NumPy may differ in the last place of transcendental functions
        np.testing.assert_allclose(*outs, rtol=2e-6, equal_nan=True)


INT_OPS = [
    "arith.add",
    "arith.sub",
    "arith.mul",
    "arith.div",
    "arith.floordiv",
    "arith.mod",
    "arith.min",
    "arith.max",
    "arith.and",
    "arith.xor",
    "arith.shl",
    "arith.shr",
]


@pytest.mark.parametrize("t", sorted(INTS))
@pytest.mark.parametrize("op", INT_OPS)
def test_int_binary(op: str, t: str) -> None:
    a, b = _pairs(INTS[t], SCALARS[t].np_dtype.name)
    _differential(_binary_kernel(op, t), a, b, SCALARS[t].np_dtype)


FLOAT_OPS = [
    "arith.add",
    "arith.div",
    "arith.floordiv",
    "arith.mod",
    "arith.min",
    "arith.max",
    "arith.pow",
    "math.atan2",
    "math.copysign",
]
INEXACT = ("arith.pow", "math.atan2")


@pytest.mark.parametrize("t", ["f16", "f32", "f64"])
@pytest.mark.parametrize("op", FLOAT_OPS)
def test_float_binary(op: str, t: str) -> None:
    with np.errstate(all="ignore"):
        a, b = _pairs(FLOATS, SCALARS[t].np_dtype.name)
        if op == "arith.pow":  # NumPy's float32 pow(-inf, 0.5) is NaN, C's powf gives inf
            keep = ~np.isneginf(a)
            a, b = a[keep], b[keep]
        _differential(_binary_kernel(op, t), a, b, SCALARS[t].np_dtype, op not in INEXACT)


@pytest.mark.parametrize("pred", ["eq", "ne", "lt", "ge"])
def test_float_compare_nan(pred: str) -> None:
    a, b = _pairs(FLOATS, "float32")
    _differential(
        _binary_kernel("arith.cmp", "f32", "bool", f' {{pred = "{pred}"}}'), a, b, np.bool_
    )


def _unary_kernel(op: str, t: str, rt: str) -> str:
    return f"""func.func @k(%a: array<{t}, 1>, %o: array<{rt}, 1>) -> () {{kind = "kernel"}} {{
  %i = kd.tid {{dim = 0, ndim = 1}} : i32
  %x = kd.load %a, %i : {t}
  %r = {op} %x : {rt}
  kd.store %r, %o, %i
  func.return
}}"""


def _unary(op: str, t: str, rt: str, a: np.ndarray, exact: bool = True) -> None:
    outs = []
    for backend in (CPU, INTERP):
        o = np.zeros(len(a), dtype=SCALARS[rt].np_dtype)
        with np.errstate(all="ignore"):
            _run(backend, _unary_kernel(op, t, rt), [a.copy(), o], len(a))
        outs.append(o)
    if exact:
        _same(*outs)
    else:
        np.testing.assert_allclose(outs[0], outs[1], rtol=2e-6, atol=1e-7, equal_nan=True)


@pytest.mark.parametrize("src", ["f16", "f32", "f64"])
@pytest.mark.parametrize("dst", ["i8", "i32", "i64", "u8", "u32", "u64", "bool", "f16", "f64"])
def test_casts(src: str, dst: str) -> None:
    a = np.array(FLOATS + [300.0, -300.0, 2.0**40, 4.5e9], dtype=SCALARS[src].np_dtype)
    with np.errstate(all="ignore"):
        _unary("arith.cast", src, dst, a)


@pytest.mark.parametrize("src", ["i8", "i64", "u32"])
@pytest.mark.parametrize("dst", ["i16", "u64", "f16", "f32", "bool"])
def test_int_casts(src: str, dst: str) -> None:
    a = np.array(INTS[src if src in INTS else "i8"], dtype=object).astype(SCALARS[src].np_dtype)
    _unary("arith.cast", src, dst, a)


@pytest.mark.parametrize(
    "op",
    [
        "math.round",
        "math.rint",
        "math.sign",
        "math.floor",
        "math.trunc",
        "math.abs",
        "math.sqrt",
        "arith.neg",
    ],
)
@pytest.mark.parametrize("t", ["f16", "f32", "f64"])
def test_exact_unary(op: str, t: str) -> None:
    _unary(op, t, t, np.array(FLOATS, dtype=SCALARS[t].np_dtype))


@pytest.mark.parametrize("op", ["math.isnan", "math.isinf", "math.isfinite"])
def test_predicates(op: str) -> None:
    _unary(op, "f32", "bool", np.array(FLOATS, dtype=np.float32))


@pytest.mark.parametrize("op", ["math.sign", "math.abs", "arith.neg", "arith.bitnot"])
def test_int_unary(op: str) -> None:
    _unary(op, "i32", "i32", np.array(INTS["i32"], dtype=np.int32))


@pytest.mark.parametrize(
    "op", ["tan", "asin", "atan", "tanh", "cbrt", "erf", "erfc", "exp", "log10", "cosh"]
)
def test_libm(op: str) -> None:
    a = np.linspace(-0.99, 0.99, 41).astype(np.float32)
    _unary(f"math.{op}", "f32", "f32", a, exact=False)


CALL = """func.func @twice(%x: f32) -> (f32, i32) {kind = "func"} {
  %y = arith.add %x, %x : f32
  %c = arith.constant {value = 7} : i32
  func.return %y, %c
}
func.func @k(%a: array<f32, 1>, %o: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %x = kd.load %a, %i : f32
  %r0, %r1 = func.call %x {callee = "twice"} : f32, i32
  %c = arith.cast %r1 : f32
  %s = arith.add %r0, %c : f32
  kd.store %s, %o, %i
  func.return
}"""


def test_call_not_inlined() -> None:
    a = np.arange(5, dtype=np.float32)
    o = np.zeros(5, dtype=np.float32)
    _run(CPU, CALL, [a, o], 5)
    np.testing.assert_array_equal(o, 2 * a + 7)


ATOMIC = """func.func @k(%a: array<f32, 1>, %o: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %z = arith.constant {value = 0} : i32
  %x = kd.load %a, %i : f32
  %r = kd.atomic_rmw %x, %o, %z {kind = "KIND"} : f32
  func.return
}"""


@pytest.mark.parametrize("kind", ["min", "max"])
def test_atomic_minmax_nan(kind: str) -> None:
    for a, init in (([3.0, np.nan, -2.0, 5.0], np.nan), ([0.0, -0.0, 0.0], -0.0)):
        outs = []
        for backend in (CPU, INTERP):
            o = np.array([init], dtype=np.float32)
            _run(backend, ATOMIC.replace("KIND", kind), [np.array(a, np.float32), o], len(a))
            outs.append(o)
        _same(*outs)


STRUCT = """struct P {s: f32, v: vec<3, f32>, on: bool}
func.func @k(%p: struct<P>, %o: array<vec<3, f32>, 1>, %f: array<bool, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %s = struct.extract %p {field = "s"} : f32
  %v = struct.extract %p {field = "v"} : vec<3, f32>
  %on = struct.extract %p {field = "on"} : bool
  %w = arith.mul %s, %v : vec<3, f32>
  %x = vec.extract %w, %i : f32
  %y = vec.insert %w, %x, %i : vec<3, f32>
  kd.store %y, %o, %i
  %n = arith.not %on : bool
  kd.store %n, %f, %i
  func.return
}"""


def test_struct_and_vector_args() -> None:
    p = (np.float32(2.0), np.array([1, 2, 3], np.float32), np.bool_(True))
    outs = []
    for backend in (CPU, INTERP):
        o = np.zeros((3, 3), np.float32)
        f = np.ones(3, np.bool_)
        _run(backend, STRUCT, [p, o, f], 3)
        outs.append((o, f))
    _same(outs[0][0], outs[1][0])
    _same(outs[0][1], outs[1][1])
    np.testing.assert_array_equal(outs[0][0][1], [2, 4, 6])
