"""Math intrinsics on f32 and f64, with their edge cases.

``round`` takes halves away from zero, ``rint`` to even, ``sign(0)`` is 1, and
``min``/``max`` with one NaN operand give the other operand.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, uniform

N = 40


def _unary_kernels(dtype):
    """One kernel per intrinsic, over one float type."""

    @wp.kernel
    def sqrt(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.sqrt(a[i])

    @wp.kernel
    def exp(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.exp(a[i])

    @wp.kernel
    def log(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.log(a[i])

    @wp.kernel
    def sin(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.sin(a[i])

    @wp.kernel
    def cos(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.cos(a[i])

    @wp.kernel
    def tan(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.tan(a[i])

    @wp.kernel
    def floor(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.floor(a[i])

    @wp.kernel
    def ceil(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.ceil(a[i])

    @wp.kernel
    def rounded(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.round(a[i])

    @wp.kernel
    def rint(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.rint(a[i])

    @wp.kernel
    def absolute(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.abs(a[i])

    @wp.kernel
    def sign(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = wp.sign(a[i])

    return {"sqrt": sqrt, "exp": exp, "log": log, "sin": sin, "cos": cos, "tan": tan,
            "floor": floor, "ceil": ceil, "round": rounded, "rint": rint, "abs": absolute,
            "sign": sign}  # fmt: skip


def _halves(rng, lo, hi):
    # Exact halves (ties for round/rint) mixed with plain values and zeros.
    a = uniform(rng, N, lo, hi, np.float64)
    a[: N // 2] = np.arange(N // 2) * 0.5 - N / 8
    a[-2:] = [0.0, -0.0]
    return a


def _round_away(x):
    return np.sign(x) * np.floor(np.abs(x) + 0.5)


#: The intrinsics' accuracy, in units in the last place of the output type: CUDA's
#: documented bounds (sin, cos, exp, log: 1 to 2 ulps in float32; tan: 4) and the
#: host libm's are within it.
ULPS = 4

#: name -> (input generator, float64 reference)
_UNARY = {
    "sqrt": (lambda rng: uniform(rng, N, 0.0, 50.0, np.float64), np.sqrt),
    "exp": (lambda rng: uniform(rng, N, -8.0, 8.0, np.float64), np.exp),
    "log": (lambda rng: uniform(rng, N, 0.01, 100.0, np.float64), np.log),
    "sin": (lambda rng: uniform(rng, N, -6.3, 6.3, np.float64), np.sin),
    "cos": (lambda rng: uniform(rng, N, -6.3, 6.3, np.float64), np.cos),
    "tan": (lambda rng: uniform(rng, N, -1.3, 1.3, np.float64), np.tan),
    "floor": (lambda rng: _halves(rng, -9.0, 9.0), np.floor),
    "ceil": (lambda rng: _halves(rng, -9.0, 9.0), np.ceil),
    "round": (lambda rng: _halves(rng, -9.0, 9.0), _round_away),
    "rint": (lambda rng: _halves(rng, -9.0, 9.0), np.rint),
    "abs": (lambda rng: _halves(rng, -9.0, 9.0), np.abs),
    "sign": (lambda rng: _halves(rng, -9.0, 9.0), lambda x: np.where(x < 0, -1.0, 1.0)),
}


def _unary_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in (("f32", wp.float32, np.float32, ()),
                                        ("f64", wp.float64, np.float64, ("fp64",))):  # fmt: skip
        for name, kernel in _unary_kernels(dtype).items():
            gen, ref = _UNARY[name]

            def make(rng, gen=gen, np_dtype=np_dtype):
                a = gen(rng).astype(np_dtype)
                return {"a": a, "out": np.zeros(N, np_dtype)}

            # The reference sees the input already rounded to the kernel's type.
            out.append(Case(f"math_{name}_{tname}", kernel, N, make,
                            lambda ins, ref=ref: {"out": ref(f64(ins["a"]))}, ("out",),
                            requires=req, ulps=ULPS))  # fmt: skip
    return out


@wp.kernel
def atan2_f32(y: wp.array(dtype=float), x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.atan2(y[i], x[i])


def _atan2_inputs(rng):
    y = uniform(rng, N, -3.0, 3.0)
    x = uniform(rng, N, -3.0, 3.0)
    y[:4] = [0.0, 1.0, -1.0, 0.0]
    x[:4] = [-1.0, 0.0, 0.0, 1.0]
    return {"y": y, "x": x, "out": np.zeros(N, np.float32)}


@wp.kernel
def min_max_nan(a: wp.array[float], b: wp.array[float], lo: wp.array[float], hi: wp.array[float]):
    i = wp.tid()
    lo[i] = wp.min(a[i], b[i])
    hi[i] = wp.max(a[i], b[i])


def _nan_inputs(rng):
    a = uniform(rng, N, -5.0, 5.0)
    b = uniform(rng, N, -5.0, 5.0)
    a[::3] = np.nan
    b[1::5] = np.nan
    return {"a": a, "b": b, "lo": np.zeros(N, np.float32), "hi": np.zeros(N, np.float32)}


@wp.kernel
def math_composite(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    # A typical mix of intrinsics, checking they compose without precision loss.
    i = wp.tid()
    x = a[i]
    out[i] = (
        wp.sqrt(x * x + 1.0) * wp.exp(-0.5 * x) + wp.sin(x) * wp.cos(2.0 * x) - wp.log(1.0 + x * x)
    )


def _composite_ref(ins):
    x = f64(ins["a"])
    return {"out": np.sqrt(x * x + 1) * np.exp(-0.5 * x) + np.sin(x) * np.cos(2 * x)
            - np.log(1 + x * x)}  # fmt: skip


CASES = [
    *_unary_cases(),
    Case("math_atan2_f32", atan2_f32, N, _atan2_inputs,
         lambda ins: {"out": np.arctan2(f64(ins["y"]), f64(ins["x"]))}, ("out",)),
    Case("math_min_max_nan", min_max_nan, N, _nan_inputs,
         lambda ins: {"lo": np.fmin(f64(ins["a"]), f64(ins["b"])),
                      "hi": np.fmax(f64(ins["a"]), f64(ins["b"]))}, ("lo", "hi")),
    Case("math_composite_f32", math_composite, N,
         lambda rng: {"a": uniform(rng, N, -3.0, 3.0), "out": np.zeros(N, np.float32)},
         _composite_ref, ("out",), tol=(1e-5, 1e-5)),
]  # fmt: skip
