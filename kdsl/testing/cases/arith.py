"""Arithmetic on f32, f64 and i32: + - * / // % min max neg pow, bitwise ops.

Integer division truncates toward zero, ``//`` floors, ``%`` takes the sign of the
dividend, and any of them by zero gives 0 (see ``kdsl.ir.semantics``). The
references below say so in NumPy, independently of the interpreter's helpers.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform

N = 64


def _kernels(dtype):
    """One kernel per binary op, for one element type (closures over ``dtype``)."""

    @wp.kernel
    def add(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] + b[i]

    @wp.kernel
    def sub(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] - b[i]

    @wp.kernel
    def mul(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] * b[i]

    @wp.kernel
    def div(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] / b[i]

    @wp.kernel
    def floordiv(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] // b[i]

    @wp.kernel
    def mod(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = a[i] % b[i]

    @wp.kernel
    def minimum(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.min(a[i], b[i])

    @wp.kernel
    def maximum(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.max(a[i], b[i])

    @wp.kernel
    def neg(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = -a[i]

    return {"add": add, "sub": sub, "mul": mul, "div": div, "floordiv": floordiv, "mod": mod,
            "min": minimum, "max": maximum, "neg": neg}  # fmt: skip


def _float_ref(op: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    x, y = f64(a), f64(b)
    if op == "floordiv":
        # Floor of the quotient rounded in the operand type: a quotient that rounds
        # to an integer in f32 must floor to it, which float64 cannot predict.
        return f64(np.floor(a / b))
    table = {
        "add": lambda: x + y, "sub": lambda: x - y, "mul": lambda: x * y,
        "div": lambda: x / y, "mod": lambda: np.fmod(x, y), "min": lambda: np.minimum(x, y),
        "max": lambda: np.maximum(x, y), "neg": lambda: -x,
    }  # fmt: skip
    return table[op]()


def _int_ref(op: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    x, y = a.astype(np.int64), b.astype(np.int64)
    safe = np.where(y == 0, 1, y)
    if op == "div":
        q = np.trunc(f64(x) / f64(safe)).astype(np.int64)
        return np.where(y == 0, 0, q)
    if op == "floordiv":
        return np.where(y == 0, 0, np.floor(f64(x) / f64(safe)).astype(np.int64))
    if op == "mod":
        return np.where(y == 0, 0, x - np.trunc(f64(x) / f64(safe)).astype(np.int64) * safe)
    table = {
        "add": lambda: x + y, "sub": lambda: x - y, "mul": lambda: x * y,
        "min": lambda: np.minimum(x, y), "max": lambda: np.maximum(x, y), "neg": lambda: -x,
    }  # fmt: skip
    return table[op]()


def _float_inputs(np_dtype, op: str):
    def make(rng):
        a = uniform(rng, N, -10.0, 10.0, np_dtype)
        b = uniform(rng, N, 0.5, 4.0, np_dtype) * rng.choice([-1, 1], N).astype(np_dtype)
        if op in ("min", "max"):
            a[::7] = b[::7]  # ties
        return {"a": a, "b": b, "out": np.zeros(N, np_dtype)}

    return make


def _int_inputs(rng):
    a = integers(rng, N, -1000, 1000)
    b = integers(rng, N, -9, 10)  # includes 0 and negatives
    a[:4] = [-7, 7, -7, 7]
    b[:4] = [2, -2, -2, 0]
    return {"a": a, "b": b, "out": np.zeros(N, np.int32)}


def _cases() -> list[Case]:
    out: list[Case] = []
    for tname, dtype, np_dtype, req in (("f32", wp.float32, np.float32, ()),
                                        ("f64", wp.float64, np.float64, ("fp64",)),
                                        ("i32", wp.int32, np.int32, ())):  # fmt: skip
        for op, kernel in _kernels(dtype).items():
            if np_dtype is np.int32:
                make, ref = (
                    _int_inputs,
                    (lambda ins, op=op: {"out": _int_ref(op, ins["a"], ins["b"])}),
                )
            else:
                make = _float_inputs(np_dtype, op)
                ref = lambda ins, op=op: {"out": _float_ref(op, ins["a"], ins["b"])}  # noqa: E731
            out.append(Case(f"arith_{op}_{tname}", kernel, N, make, ref, ("out",), requires=req))
    return out


@wp.kernel
def pow_f32(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] ** b[i]


@wp.kernel
def bitwise_i32(
    a: wp.array(dtype=wp.int32), b: wp.array(dtype=wp.int32), out: wp.array2d(dtype=wp.int32)
):
    i = wp.tid()
    s = b[i] & 31
    out[i, 0] = a[i] & b[i]
    out[i, 1] = a[i] | b[i]
    out[i, 2] = a[i] ^ b[i]
    out[i, 3] = a[i] << s
    out[i, 4] = a[i] >> s
    out[i, 5] = ~a[i]


def _bitwise_ref(ins):
    a, b = ins["a"], ins["b"]
    s = b & 31
    with np.errstate(over="ignore"):
        shl = (a.astype(np.int64) << s).astype(np.uint64).astype(np.uint32).view(np.int32)
    cols = [a & b, a | b, a ^ b, shl, a >> s, ~a]
    return {"out": np.stack(cols, axis=1)}


CASES = [
    *_cases(),
    Case("arith_pow_f32", pow_f32, N,
         lambda rng: {"a": uniform(rng, N, 0.1, 3.0), "b": uniform(rng, N, -2.0, 2.0),
                      "out": np.zeros(N, np.float32)},
         lambda ins: {"out": f64(ins["a"]) ** f64(ins["b"])}, ("out",)),
    Case("arith_bitwise_i32", bitwise_i32, N,
         lambda rng: {"a": integers(rng, N, -(2**31), 2**31 - 1),
                      "b": integers(rng, N, -100, 100), "out": np.zeros((N, 6), np.int32)},
         _bitwise_ref, ("out",)),
]  # fmt: skip
